"""Numerical tolerances and shared constants, in one place (cf. ``trimesh.constants.tol``)."""

from __future__ import annotations

#: Relative tolerance for "is this matrix singular / are these points degenerate".
RCOND = 1e-10
#: Smallest triangle area (in the units of its coordinates, squared) treated as non-degenerate.
AREA_EPS = 1e-12
#: The viseme labels of the Yano-Harada paper, in its order.
VISEMES = ("car", "man", "she", "eel", "too")
#: Number of points in an iBUG 68-point landmark file.
N_IBUG = 68
#: Share of full white a geometry-only scan's surface shows where it faces away from the light
#: (its shading stands in for the colour image: a mesh scan's render, a range scan's grid).
SHADE_AMBIENT = 0.15

#: A face scan's least relief: its depth about its best-fitting plane (1st to 99th percentile,
#: :func:`scan2morph.geometry.plane_spread`), mm, and that depth's least share of its width. The
#: synthetic heads' range grids are 55-125 mm deep, 0.2-0.5 of their width, frontal to profile (a
#: face in the wrong unit keeps its share); a surface below both is flat, a board.
MIN_FACE_RELIEF_MM = 20.0
MIN_FACE_RELIEF_SHARE = 0.1

#: A robust standard deviation is 1.4826 median absolute deviations (Gaussian data).
MAD_TO_SIGMA = 1.4826
