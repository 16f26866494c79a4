"""Tests of scan2morph.modal: shell FEM, natural modes, expression coordinates.

Frequencies are checked against classical plate theory (Leissa, Vibration of Plates, NASA
SP-160, 1969): a simply supported square plate and a clamped one; eigenpairs against ARPACK
called directly on the same matrices.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as sla
from numpy.testing import assert_allclose

from scan2morph.errors import InputError
from scan2morph.modal import (
    ModalParams,
    ShellMaterial,
    assemble,
    boundary_vertices,
    coordinate_statistics,
    fixed_dofs,
    modal_basis,
    project,
    reconstruct,
    reconstruction_error_curve,
    semantic_basis,
    solve_modes,
    thickness_map,
)

E_MPA, NU, RHO, H_MM, A_MM = 210000.0, 0.3, 7.85e-9, 1.0, 100.0


def plate_mesh(n: int, a: float = A_MM):
    """Flat square plate a x a in the z = 0 plane, n x n quads split with alternating diagonals."""
    xs = np.linspace(0.0, a, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    vertices = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    p = (j * (n + 1) + i).ravel()
    flip = ((i + j) % 2 == 1).ravel()[:, None]
    t1 = np.where(flip, np.c_[p, p + 1, p + n + 1], np.c_[p, p + 1, p + n + 2])
    t2 = np.where(flip, np.c_[p + 1, p + n + 2, p + n + 1], np.c_[p, p + n + 2, p + n + 1])
    return vertices, np.r_[t1, t2]


def cap_mesh(n: int, radii=(40.0, 50.0, 30.0)):
    """Half-ellipsoid cap (a face-like curved shell), open rim, (n+1)^2 vertices."""
    u = np.linspace(-1.0, 1.0, n + 1)
    uu, ww = np.meshgrid(u, u, indexing="xy")
    x = uu * np.sqrt(1 - ww**2 / 2)  # square -> disc
    y = ww * np.sqrt(1 - uu**2 / 2)
    z = np.sqrt(1 - 0.9 * (x**2 + y**2))
    vertices = np.c_[radii[0] * x.ravel(), radii[1] * y.ravel(), radii[2] * z.ravel()]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    p = (j * (n + 1) + i).ravel()
    faces = np.r_[np.c_[p, p + 1, p + n + 2], np.c_[p, p + n + 2, p + n + 1]]
    return vertices, faces


def plate_rigidity_speed():
    d = E_MPA * H_MM**3 / (12 * (1 - NU**2))
    return np.sqrt(d / (RHO * H_MM))  # mm^2/s


@pytest.fixture(scope="module")
def plate24():
    v, f = plate_mesh(24)
    k, m = assemble(v, f, H_MM, ShellMaterial(E_MPA, NU, RHO))
    return v, f, k, m


@pytest.fixture(scope="module")
def cap_basis():
    v, f = cap_mesh(12)
    basis = modal_basis(v, f, ModalParams(n_modes=10, upper_thickness_factor=1.0))
    return v, f, basis


# --- FEM model ---------------------------------------------------------------------------


def test_boundary_vertices_of_grid_is_its_rim():
    n = 7
    v, f = plate_mesh(n)
    rim = (v[:, 0] == 0) | (v[:, 0] == A_MM) | (v[:, 1] == 0) | (v[:, 1] == A_MM)
    assert_allclose(boundary_vertices(f), rim)
    assert boundary_vertices(f).sum() == 4 * n


def test_mass_matrix_carries_the_shell_mass_and_stiffness_ignores_rigid_motion():
    v, f = cap_mesh(8)
    t = np.random.default_rng(3).uniform(0.5, 2.0, len(f))
    mat = ShellMaterial(E_MPA, NU, RHO)
    p = v[f]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    mass = RHO * np.sum(area * t)
    rng = np.random.default_rng(4)
    omega, shift = rng.standard_normal(3), rng.standard_normal(3)
    rigid = np.zeros((len(v), 6))
    rigid[:, :3] = shift + np.cross(omega * 1e-3, v)
    rigid[:, 3:] = omega * 1e-3
    for kind in ("consistent", "lumped"):
        k, m = assemble(v, f, t, mat, mass=kind)
        assert abs(k - k.T).max() == 0 and abs(m - m.T).max() == 0
        for axis in range(3):
            e = np.zeros((len(v), 6))
            e[:, axis] = 1.0
            assert_allclose(e.ravel() @ (m @ e.ravel()), mass, rtol=1e-12)
        # a rigid motion stores no strain energy: K u = 0 up to round-off
        ku = k @ rigid.ravel()
        assert np.abs(ku).max() < 1e-9 * abs(k).max() * np.abs(rigid).max()


def test_thickness_map_thickens_upper_faces():
    f = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2]])
    up = np.array([True, True, False, False, False])
    assert_allclose(thickness_map(f, 1.0, up, 3.0), [3.0, 1.0, 1.0])
    assert_allclose(thickness_map(f, 2.0), [2.0, 2.0, 2.0])


# --- plate theory -----------------------------------------------------------------------


def test_simply_supported_plate_matches_classical_frequencies(plate24):
    v, f, k, m = plate24
    # simple support: w = 0 on the edges (u, v also held; they do not couple to bending)
    freqs, modes = solve_modes(k, m, fixed_dofs(boundary_vertices(f), "translations"), 6)
    mn2 = np.array([1 + 1, 1 + 4, 4 + 1, 4 + 4])  # (m^2 + n^2) for (1,1) (1,2) (2,1) (2,2)
    classical = (np.pi / 2) * mn2 / A_MM**2 * plate_rigidity_speed()
    assert_allclose(freqs[:4], classical, rtol=0.02)
    # these are bending modes: the in-plane translations carry no kinetic energy
    tr = modes.reshape(len(v), 6, -1)
    assert np.all(np.abs(tr[:, :2, :4]).max(axis=(0, 1)) < 1e-6 * np.abs(tr[:, 2, :4]).max(0))
    # (1,1) has no interior nodal line: one sign
    w1 = tr[:, 2, 0]
    assert np.all(w1 * np.sign(w1[np.argmax(np.abs(w1))]) >= -1e-12 * np.abs(w1).max())


def test_clamped_plate_matches_leissa_and_converges(plate24):
    v, f, k, m = plate24
    freqs, _ = solve_modes(k, m, fixed_dofs(boundary_vertices(f), "all"), 2)
    leissa = 35.99 / (2 * np.pi * A_MM**2) * plate_rigidity_speed()
    err24 = abs(freqs[0] / leissa - 1)
    assert err24 < 0.02
    v16, f16 = plate_mesh(16)
    k16, m16 = assemble(v16, f16, H_MM, ShellMaterial(E_MPA, NU, RHO))
    f16_hz, _ = solve_modes(k16, m16, fixed_dofs(boundary_vertices(f16), "all"), 2)
    assert err24 < abs(f16_hz[0] / leissa - 1)


def test_frequencies_scale_with_material_exactly():
    v, f = plate_mesh(10)
    fixed = fixed_dofs(boundary_vertices(f), "all")
    base = solve_modes(*assemble(v, f, H_MM, ShellMaterial(E_MPA, NU, RHO)), fixed, 4)[0]
    stiff = solve_modes(*assemble(v, f, H_MM, ShellMaterial(4 * E_MPA, NU, RHO)), fixed, 4)[0]
    heavy = solve_modes(*assemble(v, f, H_MM, ShellMaterial(E_MPA, NU, 4 * RHO)), fixed, 4)[0]
    assert_allclose(stiff, 2 * base, rtol=1e-9)
    assert_allclose(heavy, base / 2, rtol=1e-9)


# --- eigensolver ---------------------------------------------------------------------------


def test_block_solver_matches_arpack_on_a_curved_shell():
    v, f = cap_mesh(18)
    k, m = assemble(v, f, H_MM)
    fixed = fixed_dofs(boundary_vertices(f), "all")
    n_modes = 10
    freqs, modes = solve_modes(k, m, fixed, n_modes, method="block", block_size=4)
    # oracle: ARPACK shift-invert called directly on the free-DOF matrices
    free = np.setdiff1d(np.arange(k.shape[0]), fixed)
    kf, mf = k[free][:, free].tocsc(), m[free][:, free].tocsc()
    lam, _ = sla.eigsh(kf, k=n_modes, M=mf, sigma=0.0, which="LM")
    assert_allclose(freqs, np.sqrt(np.sort(lam)) / (2 * np.pi), rtol=1e-9)
    # mass-orthonormal, fixed DOFs zero, ascending, small residuals on the free DOFs
    assert_allclose(modes.T @ m @ modes, np.eye(n_modes), atol=1e-8)
    assert np.all(modes[fixed] == 0)
    assert np.all(np.diff(freqs) >= 0)
    lam_hz = (2 * np.pi * freqs) ** 2
    res = (k @ modes - (m @ modes) * lam_hz)[free]
    assert np.all(np.linalg.norm(res, axis=0) < 1e-8 * np.linalg.norm((k @ modes)[free], axis=0))
    arp, _ = solve_modes(k, m, fixed, n_modes, method="arpack")
    dense, _ = solve_modes(k, m, fixed, n_modes, method="dense")
    restarted, q2 = solve_modes(k, m, fixed, n_modes, block_size=3, max_basis=24)
    assert_allclose(arp, freqs, rtol=1e-9)
    assert_allclose(dense, freqs, rtol=1e-9)
    assert_allclose(restarted, freqs, rtol=1e-9)
    # same modes up to sign (the ten frequencies are distinct)
    assert_allclose(np.abs(np.sum(q2 * (m @ modes), axis=0)), 1.0, atol=1e-8)


def test_modal_basis_of_a_cap(cap_basis):
    v, f, basis = cap_basis
    assert basis.modes.shape == (10, len(v), 3)
    assert basis.dof_modes.shape == (10, len(v), 6)
    assert_allclose(basis.vectors.T @ basis.mass @ basis.vectors, np.eye(10), atol=1e-8)
    assert np.all(basis.modes[:, boundary_vertices(f)] == 0)
    assert basis.names[0] == "mode_001" and len(basis.names) == 10
    # stored frequencies are the Rayleigh quotients of the stored vectors
    rq = np.einsum("ij,ij->j", basis.vectors, basis.stiffness @ basis.vectors)
    assert_allclose(basis.frequencies_hz, np.sqrt(rq) / (2 * np.pi), rtol=1e-12)


def test_thick_upper_face_moves_the_low_modes_off_it():
    v, f = cap_mesh(12)
    upper = v[:, 1] > 0.0
    thin = modal_basis(v, f, ModalParams(n_modes=6, upper_thickness_factor=1.0), upper)
    thick = modal_basis(v, f, ModalParams(n_modes=6, upper_thickness_factor=5.0), upper)
    assert_allclose(np.unique(thick.thickness_mm), [1.0, 5.0])

    def upper_share(b):
        amp = np.sum(b.modes**2, axis=2)  # (k, V)
        return np.mean(amp[:, upper].sum(axis=1) / amp.sum(axis=1))

    assert upper_share(thin) > 0.35
    assert upper_share(thick) < 0.15


# --- expression coordinates --------------------------------------------------------------


def test_projection_recovers_the_coordinates_of_a_modal_field(cap_basis):
    v, _, basis = cap_basis
    c = np.random.default_rng(7).standard_normal(basis.n_modes)
    field = (basis.vectors @ c).reshape(len(v), 6)
    assert_allclose(project(basis, field), c, atol=1e-8 * np.abs(c).max())
    both = project(basis, np.stack([field, 2 * field]))
    assert_allclose(both, [c, 2 * c], atol=1e-8 * np.abs(c).max())
    assert_allclose(reconstruct(basis, c), field[:, :3], atol=1e-12)
    assert_allclose(reconstruct(basis, c, 0), 0.0)


def test_reconstruction_error_decreases_with_the_number_of_modes(cap_basis):
    v, f, basis = cap_basis
    rng = np.random.default_rng(11)
    # a smooth bulge plus noise, zero on the rim
    field = np.exp(-((v[:, :1] - 5) ** 2 + v[:, 1:2] ** 2) / 300.0) * [0.0, 0.0, 2.0]
    field = field + 0.05 * rng.standard_normal(field.shape)
    field[boundary_vertices(f)] = 0.0
    ks = np.arange(0, basis.n_modes + 1)
    err = reconstruction_error_curve(basis, field, ks)
    assert np.all(np.diff(err) <= 1e-12 * err[0])
    assert err[-1] < err[0]
    # K = 0: the mass-weighted RMS of the field itself
    vec = np.zeros((len(v), 6))
    vec[:, :3] = field
    total = float(basis.mass[0::6, 0::6].sum())
    assert_allclose(err[0], np.sqrt(vec.ravel() @ basis.mass @ vec.ravel() / total), rtol=1e-12)
    plain = reconstruction_error_curve(basis, field, [0], weighting="vertex")
    assert_allclose(plain[0], np.sqrt(np.mean(np.sum(field**2, axis=1))), rtol=1e-12)


def test_semantic_basis_reproduces_inserted_expressions(cap_basis):
    v, f, basis = cap_basis
    rng = np.random.default_rng(5)
    smile = np.zeros((len(v), 3))
    smile[:, 0] = np.sin(v[:, 0] / 10.0)
    smile[:, 2] = 0.5 * np.cos(v[:, 1] / 15.0)
    sad = rng.standard_normal((len(v), 3))
    sem = semantic_basis(basis, [smile, sad], ["smile", "sad"])
    assert sem.n_modes == basis.n_modes
    assert sem.names[:3] == ("smile", "sad", "modified_001")
    assert_allclose(sem.vectors.T @ sem.mass @ sem.vectors, np.eye(sem.n_modes), atol=1e-8)
    q = project(sem, smile)
    assert abs(q[0]) > 0
    assert np.all(np.abs(q[1:]) < 1e-8 * abs(q[0]))
    assert_allclose(reconstruct(sem, q, 1), smile, atol=1e-10)
    # an expression in the span of the natural modes makes one natural mode dependent
    inside = (basis.vectors[:, :3] @ [1.0, -2.0, 0.5]).reshape(len(v), 6)
    sem2 = semantic_basis(basis, [inside], ["inside"], n_modes=basis.n_modes + 5)
    assert sem2.n_modes == basis.n_modes
    assert sum(name.startswith("modified") for name in sem2.names) == basis.n_modes - 1


def test_coordinate_statistics_per_label():
    rng = np.random.default_rng(2)
    coords = {f"t{i}": rng.standard_normal(6) for i in range(5)}
    labels = {"t0": "smile", "t1": "smile", "t2": "smile", "t3": "sad", "t4": "eel"}
    stats = coordinate_statistics(coords, labels)
    assert list(stats) == ["eel", "sad", "smile"]
    x = np.stack([coords["t0"], coords["t1"], coords["t2"]])
    assert_allclose(stats["smile"].mean, x.mean(0))
    assert_allclose(stats["smile"].std, np.std(x, axis=0, ddof=1))
    assert stats["smile"].n == 3 and stats["sad"].takes == ("t3",)
    assert np.all(np.isnan(stats["sad"].std))


# --- bad input --------------------------------------------------------------------------


def test_bad_meshes_raise():
    tet_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    tet_f = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    with pytest.raises(InputError, match="no boundary"):
        modal_basis(tet_v, tet_f, ModalParams(n_modes=2))
    v, f = plate_mesh(3)
    v_bad = v.copy()
    v_bad[f[4, 2]] = v_bad[f[4, 0]]  # collapse triangle 4 onto an edge
    with pytest.raises(InputError, match="triangle 4 is degenerate"):
        assemble(v_bad, f)
    with pytest.raises(InputError, match="vertices: expected shape"):
        assemble(v[:, :2], f)
    with pytest.raises(InputError, match="faces: indices"):
        assemble(v, f + 100)
    with pytest.raises(InputError, match="faces: expected integer"):
        assemble(v, f.astype(float))
    with pytest.raises(InputError, match="finite"):
        assemble(np.where(v == 0, np.nan, v), f)
    # a second, closed part (tetrahedron) floats: nothing holds it
    v2 = np.r_[v, tet_v + 200.0]
    f2 = np.r_[f, tet_f + len(v)]
    with pytest.raises(InputError, match="connected part"):
        modal_basis(v2, f2, ModalParams(n_modes=2))


def test_bad_material_and_thickness_raise():
    v, f = plate_mesh(3)
    with pytest.raises(InputError, match="youngs_modulus_mpa"):
        assemble(v, f, 1.0, ShellMaterial(youngs_modulus_mpa=0.0))
    with pytest.raises(InputError, match="density_t_per_mm3"):
        assemble(v, f, 1.0, ShellMaterial(density_t_per_mm3=-1.0))
    with pytest.raises(InputError, match="poisson_ratio"):
        assemble(v, f, 1.0, ShellMaterial(poisson_ratio=0.5))
    with pytest.raises(InputError, match="thickness_mm: expected positive values, face 2"):
        assemble(v, f, np.where(np.arange(len(f)) == 2, 0.0, 1.0))
    with pytest.raises(InputError, match=r"thickness_mm: expected a float or shape"):
        assemble(v, f, np.ones(3))
    with pytest.raises(InputError, match="thickness_mm"):
        thickness_map(f, -1.0)
    with pytest.raises(InputError, match="upper_factor"):
        thickness_map(f, 1.0, np.ones(len(v), bool), 0.0)
    with pytest.raises(InputError, match="upper_face"):
        thickness_map(f, 1.0, np.ones(3, bool), 2.0)
    with pytest.raises(InputError, match="element"):
        assemble(v, f, element="quad4")
    with pytest.raises(InputError, match="mass"):
        assemble(v, f, mass="diagonal")
    with pytest.raises(InputError, match="boundary"):
        modal_basis(v, f, ModalParams(n_modes=2, boundary="free"))


def test_bad_eigen_requests_raise():
    v, f = plate_mesh(3)
    k, m = assemble(v, f)
    fixed = fixed_dofs(boundary_vertices(f), "all")
    n_free = k.shape[0] - fixed.size
    with pytest.raises(InputError, match=r"k: expected an integer in \[1, 23\]"):
        solve_modes(k, m, fixed, n_free)
    with pytest.raises(InputError, match="k: expected"):
        modal_basis(v, f, ModalParams(n_modes=500))
    with pytest.raises(InputError, match="method"):
        solve_modes(k, m, fixed, 2, method="lobpcg")
    with pytest.raises(InputError, match="fixed_dofs"):
        solve_modes(k, m, [k.shape[0]], 2)
    with pytest.raises(InputError, match="square"):
        solve_modes(k[:, :-1], m, fixed, 2)
    with pytest.raises(InputError, match="components"):
        fixed_dofs(boundary_vertices(f), "rotations")
    with pytest.raises(InputError, match="not held|singular"):
        solve_modes(k, m, [], 2)  # nothing fixed: rigid-body motions, K singular


def test_bad_projection_input_raises(cap_basis):
    v, _, basis = cap_basis
    with pytest.raises(InputError, match="displacement: expected shape"):
        project(basis, np.zeros((len(v) - 1, 3)))
    with pytest.raises(InputError, match="finite"):
        project(basis, np.full((len(v), 3), np.nan))
    with pytest.raises(InputError, match="expected shape"):
        reconstruct(basis, np.zeros(3))
    with pytest.raises(InputError, match="n_modes"):
        reconstruct(basis, np.zeros(basis.n_modes), basis.n_modes + 1)
    with pytest.raises(InputError, match="ks"):
        reconstruction_error_curve(basis, np.zeros((len(v), 3)), [basis.n_modes + 1])
    with pytest.raises(InputError, match="weighting"):
        reconstruction_error_curve(basis, np.zeros((len(v), 3)), [1], weighting="max")
    field = np.random.default_rng(0).standard_normal((len(v), 3))
    with pytest.raises(InputError, match="one name per field"):
        semantic_basis(basis, [field], ["a", "b"])
    with pytest.raises(InputError, match="distinct"):
        semantic_basis(basis, [field, 2 * field], ["a", "a"])
    with pytest.raises(InputError, match="'b': linearly dependent"):
        semantic_basis(basis, [field, 2 * field], ["a", "b"])
    with pytest.raises(InputError, match="zero mass norm"):
        semantic_basis(basis, [np.zeros((len(v), 3))], ["a"])
    with pytest.raises(InputError, match="no label"):
        coordinate_statistics({"t0": np.zeros(3)}, {})
    with pytest.raises(InputError, match="one length"):
        coordinate_statistics({"a": np.zeros(3), "b": np.zeros(4)}, {"a": "x", "b": "x"})
