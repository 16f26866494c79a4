"""Modal basis of the neutral face and expression coordinates (the modal analysis paper).

The neutral mesh becomes a finite element model (:mod:`.fem`: pyfe3d shell triangles, and for
the ``skin`` physics a tension, a foundation and a tether on the translations,
:func:`.skin.skin_stiffness`, softer where the mimic muscles move the skin), held where :mod:`.boundary` says (the whole outline, its still part,
or nowhere); its lowest natural modes (:mod:`.eigen`, :mod:`.basis`) form a mass-orthonormal basis
in which expression displacement fields get their coordinates (:mod:`.project`; their
reconstruction error split into normal and tangential parts), optionally after inserting
identified expressions as "semantic" vectors. :mod:`.span` measures what a basis spans (least
squares on its first K fields) and builds the smooth intrinsic anchor (Laplace-Beltrami
eigenfunctions per axis). Units: mm, N, tonne, s (frequencies in Hz).
"""

from scan2morph.modal.basis import Held, ModalBasis, ModalParams, modal_basis
from scan2morph.modal.eigen import SolverOptions, solve_modes
from scan2morph.modal.fem import (
    ShellMaterial,
    assemble,
    boundary_vertices,
    fixed_dofs,
    thickness_map,
)
from scan2morph.modal.project import (
    CoordinateStats,
    coordinate_statistics,
    project,
    reconstruct,
    reconstruction_error_curve,
    reconstruction_split,
    semantic_basis,
)
from scan2morph.modal.skin import mimic_skin, skin_stiffness

__all__ = [
    "CoordinateStats",
    "Held",
    "ModalBasis",
    "ModalParams",
    "ShellMaterial",
    "assemble",
    "boundary_vertices",
    "coordinate_statistics",
    "fixed_dofs",
    "mimic_skin",
    "modal_basis",
    "project",
    "reconstruct",
    "reconstruction_error_curve",
    "reconstruction_split",
    "semantic_basis",
    "skin_stiffness",
    "SolverOptions",
    "solve_modes",
    "thickness_map",
]
