"""``leafview.beam``: the cantilever beam of seed 002 (eq. 4); see :mod:`leafview.model.beam`."""

from .model.beam import BEND_SAMPLES, BendProfile, bend_profile, residual, solve_bending

__all__ = ["solve_bending", "residual", "bend_profile", "BendProfile", "BEND_SAMPLES"]
