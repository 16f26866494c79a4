"""Dense stereo reconstruction: a calibrated image pair to an organised range image.

The pipeline (OpenCV throughout):

1. **rectify** both images (:func:`cv2.stereoRectify` with zero disparity at infinity, then
   :func:`cv2.initUndistortRectifyMap` / :func:`cv2.remap`), keeping every source pixel
   (``alpha = 1``) at the source resolution (the rectified canvas grows instead);
2. the **disparity search range**: from ``min_depth_mm``/``max_depth_mm`` when given, else
   (the default) **derived from the pair** by a coarse pass (a Gaussian pyramid of the rectified
   pair, semi-global matching over depths of 0.2-5 m, the robust disparity extent of the
   textured surfaces both views see, plus ``depth_margin_mm``), so that rigs at any working
   distance, baseline and image size work untuned;
3. **dense disparity** by semi-global matching (:func:`cv2.StereoSGBM_create`, 1/16 px) of the
   left view and of the right view (:func:`cv2.ximgproc.createRightMatcher`), on a canvas padded
   so that SGBM's unmatched border bands hold no image content;
4. a **left-right consistency check** (the two disparities must agree within
   ``lr_max_diff_px``); optionally opencv-contrib's WLS filter
   (:func:`cv2.ximgproc.createDisparityWLSFilter`), still masked by the check because WLS fills
   holes with guesses; pixels without local texture are dropped (SGM propagates guesses into
   them);
5. **sub-pixel refinement** of SGBM's disparity by windowed Gauss-Newton on locally normalised
   images (removes the pixel-locking bias of SGBM's parabola fit), then **per pixel** with a
   small slanted window (the window follows the local disparity gradient and curvature, so
   slanted, foreshortened and curved surfaces match too, and tips and ridges are not
   flattened);
6. **growth**: unmatched pixels next to matched ones get the disparity extrapolated from their
   neighbours' planes, a short local search and the per-pixel refinement; they are kept when
   their slanted window matches (SGBM's fronto-parallel windows miss much of the steep skin
   next to occlusions, along the nose and the jaw);
7. **validation per pixel** instead of blanket bands: every pixel (grown ones included) must
   match with its slanted window (ZNCC) and agree with the right view (left-right check); at a
   depth discontinuity only the **background side** is trimmed, a narrow band where window
   matching sticks to the wrong surface (the occluded side of an occlusion gap along the
   epipolar line, and the pixels a foreground edge looks down on); small disconnected
   segments are dropped and small holes enclosed by a consistent plane are filled;
8. **resampling into the unrectified left image grid**: every left pixel is mapped to its
   rectified position (:func:`cv2.undistortPoints` with ``R=R1, P=P1``); it gets a point when
   the nearest rectified pixel is valid, with the disparity interpolated bilinearly over the
   four neighbours (a neighbour that is missing or more than ``max_step_px`` off the nearest
   one is completed from the plane of the other three, else replaced by the nearest one); the
   point ``Q @ (u, v, d, 1)`` (what :func:`cv2.reprojectImageTo3D` computes per pixel) is
   formed and rotated back from the rectified into the unrectified left camera frame
   (``R1^T``).

The result is the organised range image of a range scan, pixel to pixel with the left color
image: ``xyz[y, x]`` lies on the (undistorted) ray of left pixel ``(x, y)``.

Interpolating the disparity rather than the rectified XYZ is deliberate: disparity is an affine
function of the rectified pixel on a plane, so the interpolation is exact for planar patches and
the point stays exactly on the pixel's ray.

Measured on the 30 default synthetic stereo takes (3 subjects x 10 labels, config parameters)
over the face region: the per-pixel validation, the growth and the background-side trim (which
replaced a 4 px band around every depth edge and a 1 px erosion of every hole) give depth RMS
0.40 mm (0.26-0.49; before 0.45, 0.33-1.59) and coverage 0.88 (0.85-0.91; before 0.84,
0.80-0.87), median error 0.11 mm (0.15). The rest of the face is mostly hidden from the right
camera (1.4-2.3 %) or seen by it at a grazing angle (disparity gradient above 0.5 px/px,
2-4 %), where no window matches; the remaining errors sit within 3 px of occlusions and depth
steps. Since then Lanczos rectification and windows that follow the disparity's curvature
(``benchmarks/bench_stereo_takes.py``, 8 takes of 2 subjects: neutral, car, smile, sad) took
the depth RMS from 0.419 to 0.325 mm and the median from 0.107 to 0.076 mm, at 0.873 coverage
instead of 0.884; the median signed error where the true surface is most convex (range
Laplacian above 0.1 mm/px^2) from +0.164 to +0.107 mm.

The package holds one module per stage: ``params`` (:data:`DEFAULT_STEREO`, the checks of
:func:`stereo_params`), ``rectify`` (rectification, remap tables), ``depth_range`` (the depth
range of the search, configured or derived by the coarse pass), ``sgbm`` (search range,
padding, the semi-global matcher, the left-right check), ``windowed`` (texture measure and
windowed sub-pixel refinement), ``slanted`` (the per-pixel slanted-window matcher, its
refinement, growth and validation), ``cleanup`` (edge trim, segments, hole filling),
``resample`` (disparity to points of the left image grid), ``views`` (the pair checked, made
grey, rectified and padded for matching) and ``reconstruct`` (the driver,
:func:`reconstruct_stereo`).
"""

from scan2morph.scan.stereo.params import DEFAULT_STEREO, stereo_params
from scan2morph.scan.stereo.reconstruct import reconstruct_stereo

__all__ = ["DEFAULT_STEREO", "reconstruct_stereo", "stereo_params"]
