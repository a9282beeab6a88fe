"""Public name of the landmark leaf model (Garg & Leow 2011, eqs 1-6):
``from leafview.landmarks import fit_margin``. The implementation is
:mod:`leafview.botany.landmarks`; this module re-exports its public API unchanged."""

from __future__ import annotations

from leafview.botany.landmarks import *  # noqa: F403
from leafview.botany.landmarks import __all__ as _botany_all

__all__ = list(_botany_all)
