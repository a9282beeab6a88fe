"""Botanical shapes: landmarks and quadratic B-spline margins (Garg & Leow 2011, eqs 1-6), the
shape catalogue of Table 1, asymmetric and lobed leaves, morphing in leaf space (eqs 10-11), and
the fits of those outlines to the shader model Ω; and the vein tree of a leaf (Hong 2005, ch. 6.1;
:mod:`.venation`). Imports :mod:`leafview.core` and :mod:`leafview.deform`.
"""
