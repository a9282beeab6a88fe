"""Fitting the leaf model to captured data (Chaurasia & Beardsley 2017, secs 4-5).

* :mod:`leafview.fit.cloud`: one leaf's point cloud to Ω and a placement (sec. 5, eqs 9-11).
* :mod:`leafview.fit.views`: RGB-D views on disk (colour, depth, camera) and their 3D points.
* :mod:`leafview.fit.segment` and :mod:`leafview.fit.capture`: dense foliage from RGB-D views
  to a leaf set (sec. 4).
* :mod:`leafview.fit.evaluate`: a capture scored against the truth it was rendered from.
* :mod:`leafview.fit.synthetic`: occluded, noisy clouds of known leaves (tests, benchmarks).
* :mod:`leafview.fit.photo_io`, :mod:`leafview.fit.photo_outline` and
  :mod:`leafview.fit.photo_shape`: a photograph read, the leaf segmented and traced, its base,
  apex and petiole found (:func:`leaf_outline`).
* :mod:`leafview.fit.photo` and :mod:`leafview.fit.photo_texture`: a leaf from a photograph or
  scan: Ω, scale and front texture (:func:`fit_image`).
* :mod:`leafview.fit.synthetic_photos`: seeded synthetic leaf photos on paper with their truth
  (tests, benchmarks).

numpy, scipy and scikit-image only: nothing here imports OpenGL.
"""

from leafview.fit.capture import CaptureResult  # the function: leafview.fit.capture.capture (the module keeps its name)
from leafview.fit.cloud import FitResult, fit_cloud, sample_leaf, surface_distance
from leafview.fit.cloud_io import read_cloud
from leafview.fit.evaluate import CaptureEvaluation, evaluate_capture
from leafview.fit.photo import ImageFit, fit_image
from leafview.fit.photo_outline import LeafOutline, leaf_outline, read_photo
from leafview.fit.views import View, read_views

__all__ = ["CaptureEvaluation", "CaptureResult", "FitResult", "ImageFit", "LeafOutline", "View", "evaluate_capture",
           "fit_cloud", "fit_image", "leaf_outline", "read_cloud", "read_photo", "read_views", "sample_leaf",
           "surface_distance"]
