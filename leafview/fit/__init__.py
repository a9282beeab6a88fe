"""Fitting the leaf model to captured data (Chaurasia & Beardsley 2017, secs 4-5).

* :mod:`leafview.fit.cloud`: one leaf's point cloud to Ω and a placement (sec. 5, eqs 9-11).
* :mod:`leafview.fit.views`: RGB-D views on disk (colour, depth, camera) and their 3D points.
* :mod:`leafview.fit.segment` and :mod:`leafview.fit.capture`: dense foliage from RGB-D views
  to a leaf set (sec. 4).
* :mod:`leafview.fit.evaluate`: a capture scored against the truth it was rendered from.
* :mod:`leafview.fit.synthetic`: occluded, noisy clouds of known leaves (tests, benchmarks).

numpy, scipy and scikit-image only: nothing here imports OpenGL.
"""

from leafview.fit.capture import CaptureResult  # the function: leafview.fit.capture.capture (the module keeps its name)
from leafview.fit.cloud import FitResult, fit_cloud, sample_leaf, surface_distance
from leafview.fit.cloud_io import read_cloud
from leafview.fit.evaluate import CaptureEvaluation, evaluate_capture
from leafview.fit.views import View, read_views

__all__ = ["CaptureEvaluation", "CaptureResult", "FitResult", "View", "evaluate_capture", "fit_cloud",
           "read_cloud", "read_views", "sample_leaf", "surface_distance"]
