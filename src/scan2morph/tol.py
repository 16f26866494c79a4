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

#: A robust standard deviation is 1.4826 median absolute deviations (Gaussian data).
MAD_TO_SIGMA = 1.4826
