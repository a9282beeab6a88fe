"""``leafview.beam``: the cantilever beam (Geng, Hu & Zhang 2014, eq. 4); the implementation is
:mod:`leafview.deform.beam`."""

from leafview.deform.beam import BEND_SAMPLES, BendProfile, bend_profile, residual, solve_bending

__all__ = ["solve_bending", "residual", "bend_profile", "BendProfile", "BEND_SAMPLES"]
