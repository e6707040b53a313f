"""Steady-state friction tables (``kind: levels``): Kt, mu and the coupling fitted
through the friction ratios ON/OFF (docs/how-to/levels-table.md)."""
