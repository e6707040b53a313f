"""The bench data format v1 as JSON Schema files (see README.md in this folder).

Installed as ``idtool.datasets_schema`` (pyproject ``package-dir``) so the loader reads the
same files that other languages use; this package holds data only.
"""
