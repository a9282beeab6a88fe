"""Public name of the landmark leaf model: ``from leafview.landmarks import fit_margin``.

The implementation lives in :mod:`leafview.model.landmarks` (numpy/scipy only, with the model
package); this module re-exports its public API unchanged so that user code and the docs use one
short import path.
"""

from __future__ import annotations

from .model.landmarks import *  # noqa: F401,F403
from .model.landmarks import __all__ as _model_all

__all__ = list(_model_all)
