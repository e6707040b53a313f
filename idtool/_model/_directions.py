"""Every direction of vibration, registered: import :data:`DIRECTIONS` from here.

:mod:`idtool._model._direction` holds the interface and the registry; each direction is
a module of its own that registers itself on import (``along``, ``normal``,
``transverse``: the registry lists them in import order). This module imports them all,
so the registry it exports is full, without a circle between the interface and the
directions.
"""

from __future__ import annotations

from idtool._model._direction import DIRECTIONS, AbstractDirection
from idtool._model._direction_along import Along
from idtool._model._direction_normal import Normal
from idtool._model._direction_transverse import Transverse
from idtool._model._names import DEFAULT_DIRECTION

__all__ = ["DEFAULT_DIRECTION", "DIRECTIONS", "AbstractDirection", "Along", "Normal", "Transverse"]
