"""Public name of the botanical shape catalogue (Garg & Leow 2011, Table 1 and Fig. 5) as
shader-model leaves: ``leafview.shapes.catalogue()``, ``leafview.shapes.shapes_params(name)``.
The implementation is :mod:`leafview.botany.shapes`; this module re-exports its public API."""

from __future__ import annotations

from leafview.botany.shapes import *  # noqa: F403
from leafview.botany.shapes import __all__ as _botany_all

__all__ = list(_botany_all)
