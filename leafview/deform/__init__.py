"""Deformations of the blade (Geng, Hu & Zhang 2014): fBm signals by spectral synthesis
(:mod:`.fbm`, eqs 1-3), the cantilever beam (:mod:`.beam`, eq. 4), and the whole leaf surface with
rippled margins and a bent midrib (:mod:`.surface`), the numpy twin of the vertex shader.
Imports :mod:`leafview.core` only.
"""
