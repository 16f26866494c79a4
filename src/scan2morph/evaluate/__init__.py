"""Accuracy of the pipeline's results against ground truth (synthetic takes)."""

from scan2morph.evaluate.scan import face_region, stereo_accuracy

__all__ = ["face_region", "stereo_accuracy"]
