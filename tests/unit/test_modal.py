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
    SolverOptions,
    assemble,
    boundary_vertices,
    coordinate_statistics,
    fixed_dofs,
    modal_basis,
    project,
    reconstruct,
    reconstruction_error_curve,
    reconstruction_split,
    semantic_basis,
    skin_stiffness,
    solve_modes,
    thickness_map,
)
from scan2morph.modal.boundary import outline_motion, still_outline
from scan2morph.modal.subject import ExpressionFields, NeutralShell, subject_modal
from scan2morph.store import paths
from tests.support.meshes import plate_mesh

E_MPA, NU, RHO, H_MM, A_MM = 210000.0, 0.3, 7.85e-9, 1.0, 100.0


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
    freqs, modes = solve_modes(k, m, fixed, n_modes, SolverOptions(method="block", block_size=4))
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
    arp, _ = solve_modes(k, m, fixed, n_modes, SolverOptions(method="arpack"))
    dense, _ = solve_modes(k, m, fixed, n_modes, SolverOptions(method="dense"))
    restarted, q2 = solve_modes(k, m, fixed, n_modes, SolverOptions(block_size=3, max_basis=24))
    assert_allclose(arp, freqs, rtol=1e-9)
    assert_allclose(dense, freqs, rtol=1e-9)
    assert_allclose(restarted, freqs, rtol=1e-9)
    # same modes up to sign (the ten frequencies are distinct)
    assert_allclose(np.abs(np.sum(q2 * (m @ modes), axis=0)), 1.0, atol=1e-8)


def test_block_solver_with_massless_rotations():
    # The skin preset's kind of model: no rotary inertia, so half of M's rows are zero and the
    # solver keeps M times its basis on the other half; a free rim held by the skin's tension
    # and foundation. Oracle: ARPACK shift-invert called directly on the pencil (M semidefinite:
    # it agrees with the dense pencil to 7e-15, in a fortieth of its 1.1 s).
    v, f = cap_mesh(18)
    k, m = assemble(v, f, H_MM, ShellMaterial(0.01, NU, 1.1e-9, rotary_inertia=False))
    k = (k + skin_stiffness(v, f, 1.0, 0.01)).tocsc()
    assert np.count_nonzero(m.diagonal()) == 3 * len(v)
    n_modes = 12
    lam, _ = sla.eigsh(k, k=n_modes, M=m.tocsc(), sigma=0.0, which="LM")
    oracle = np.sqrt(np.sort(lam)) / (2 * np.pi)
    for size, basis in ((4, None), (3, 30)):  # with and without thick restarts
        freqs, modes = solve_modes(
            k, m, [], n_modes, SolverOptions(block_size=size, max_basis=basis)
        )
        assert_allclose(freqs, oracle, rtol=1e-9)
        assert_allclose(modes.T @ m @ modes, np.eye(n_modes), atol=1e-8)
        res = k @ modes - (m @ modes) * (2 * np.pi * freqs) ** 2
        assert np.all(np.linalg.norm(res, axis=0) < 1e-8 * np.linalg.norm(k @ modes, axis=0))


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


def _split_by_hand(field, normals):
    along = np.einsum("vd,vd->v", field, normals)
    tangent = field - along[:, None] * normals
    return (
        np.sqrt(np.mean(np.sum(field**2, axis=1))),
        np.sqrt(np.mean(along**2)),
        np.sqrt(np.mean(np.sum(tangent**2, axis=1))),
    )


def test_reconstruction_split_of_a_modal_field_is_exact(cap_basis):
    """A field that is exactly a combination of the first 4 modes rebuilds to 0 from K = 4 on;
    below, every part equals the part of the missing modes' field computed by hand."""
    v, f, basis = cap_basis
    from scan2morph.geometry import vertex_normals

    normals = vertex_normals(v, f)
    c = np.array([1.0, -0.5, 0.3, 0.8]) * 1e-3
    field = (basis.vectors[:, :4] @ c).reshape(len(v), 6)
    ks = [0, 1, 2, 4, basis.n_modes]
    split = reconstruction_split(basis, field, normals, ks, target_mm=1e-9)
    assert_allclose(split.ks, ks)
    scale = np.sqrt(np.mean(np.sum(field[:, :3] ** 2, axis=1)))
    for i, kk in enumerate(ks):
        rest = field[:, :3] - reconstruct(basis, np.r_[c, np.zeros(basis.n_modes - 4)], kk)
        want = _split_by_hand(rest, normals)
        got = (split.total_mm[i], split.normal_mm[i], split.tangential_mm[i])
        assert_allclose(got, want, atol=1e-9 * scale)
    assert np.all(np.array([split.total_mm[-2], split.total_mm[-1]]) < 1e-10 * scale)
    assert split.modes_to_target == 4.0
    # a target the field itself is within: no mode (K = 0), not the first
    assert reconstruction_split(basis, field, normals, ks, 1.01 * scale).modes_to_target == 0.0
    # a target no K reaches: NaN
    far = reconstruction_split(basis, np.ones((len(v), 3)), normals, [1], target_mm=1e-6)
    assert np.isnan(far.modes_to_target)


def test_reconstruction_split_of_an_in_plane_field_on_a_plate_is_all_tangential():
    """On a flat plate the low modes bend it (w, r_x, r_y) and the consistent mass does not
    couple them to in-plane motion: an in-plane field has no coordinate on them, and its error
    stays the field itself, all tangential, at every K."""
    v, f = plate_mesh(8)
    basis = modal_basis(v, f, ModalParams(n_modes=8, upper_thickness_factor=1.0))
    assert np.abs(basis.dof_modes[:, :, :2]).max() < 1e-9 * np.abs(basis.dof_modes).max()
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    rng = np.random.default_rng(3)
    field = np.c_[rng.standard_normal((len(v), 2)), np.zeros(len(v))]
    split = reconstruction_split(basis, field, normals, [0, 1, 4, 8])
    rms = np.sqrt(np.mean(np.sum(field**2, axis=1)))
    assert_allclose(split.total_mm, rms, rtol=1e-9)
    assert_allclose(split.tangential_mm, rms, rtol=1e-9)
    assert np.all(split.normal_mm < 1e-9 * rms)
    # and a purely normal field keeps no tangential error (the modes are normal too)
    bulge = np.c_[np.zeros((len(v), 2)), np.sin(np.pi * v[:, 0] / A_MM)]
    normal = reconstruction_split(basis, bulge, normals, [0, 1, 8])
    assert np.all(normal.tangential_mm < 1e-9)
    assert_allclose(normal.normal_mm, normal.total_mm, rtol=1e-12)
    assert normal.total_mm[-1] < normal.total_mm[0]


def _loop(n):
    """A loop of n vertices (indices 0 .. n-1) and its angles."""
    return np.arange(n), np.linspace(0, 2 * np.pi, n, endpoint=False)


def test_still_outline_clamps_where_the_takes_do_not_move():
    loop, ang = _loop(40)
    moving = np.sin(ang) > 0.1  # the lower half of the loop moves (the jaw)
    fields = []
    for amp in (2.0, 3.0, 5.0):
        field = np.zeros((40, 3))
        field[moving, 1] = amp
        fields.append(field)
    fields[0][5] = [0.0, 9.0, 0.0]  # one wild vertex in one take: the median ignores it
    fields[1][30] = np.nan  # a take without a value there
    choice = still_outline(loop, fields, 40, "still", still_mm=1.0)
    np.testing.assert_array_equal(choice.fixed, ~moving)
    np.testing.assert_array_equal(choice.outline, np.ones(40, dtype=bool))
    # the median over the takes is 3 mm on the moving part, 0 on the still part
    assert_allclose(choice.motion_mm[moving][3:-3], 3.0)
    assert_allclose(choice.motion_mm[~moving], 0.0)
    # the paper: the whole outline
    paper = still_outline(loop, fields, 40, "all")
    assert paper.fixed.all()
    # too few still vertices: the stillest min_fixed_share of them
    everything = [np.tile([0.0, 2.0, 0.0], (40, 1)) * (1 + np.cos(ang))[:, None]]
    few = still_outline(loop, everything, 40, "still", still_mm=0.01, min_fixed_share=0.25)
    assert few.fixed.sum() == 10
    assert np.all(np.abs(np.cos(ang[few.fixed])) > 0.7)  # round angle pi, where 1 + cos = 0
    assert np.all(np.cos(ang[few.fixed]) < 0)
    # no takes: the whole outline
    assert still_outline(loop, [], 40, "still").fixed.all()
    with pytest.raises(InputError, match="fixed_outline"):
        still_outline(loop, fields, 40, "some")
    with pytest.raises(InputError, match="min_fixed_share"):
        still_outline(loop, fields, 40, "still", min_fixed_share=0.0)
    with pytest.raises(InputError, match="expected shape"):
        outline_motion(loop, [np.zeros((39, 3))], 40)


def test_subject_modal_stores_the_split_and_the_outline(cap_basis):
    """A field that moves only the free part of the rim: nothing of it sits on the clamped
    vertices, and the stored split equals reconstruction_split's."""
    v, f, _ = cap_basis
    rim = np.flatnonzero(boundary_vertices(f))
    centre = v[rim, :2].mean(axis=0)
    order = np.argsort(np.arctan2(v[rim, 1] - centre[1], v[rim, 0] - centre[0]))
    loop = rim[order]
    field = np.zeros_like(v)
    low = v[:, 1] < -10.0
    field[low, 1] = 0.5
    choice = still_outline(loop, [field], len(v), "still", still_mm=0.05)
    assert 0 < choice.fixed.sum() < len(loop)
    params = ModalParams(n_modes=10, upper_thickness_factor=1.0)
    shell = NeutralShell(v, f, np.zeros(len(v), bool))
    expressions = ExpressionFields({"e1": field}, {"e1": "smile"}, [], [1, 5], target_mm=0.5)
    basis, data = subject_modal(shell, params, expressions, "cap", fixed=choice)
    np.testing.assert_array_equal(data[paths.modal("fixed_vertices")], choice.fixed)
    np.testing.assert_array_equal(data[paths.modal("outline_vertices")], choice.outline)
    assert data[paths.expression("e1", "clamped_rms_mm")] == 0.0
    on_rim = np.sqrt(np.mean(np.sum(field[loop] ** 2, axis=1)))
    assert_allclose(data[paths.expression("e1", "outline_rms_mm")], on_rim, rtol=1e-12)
    from scan2morph.geometry import vertex_normals

    split = reconstruction_split(basis, field, vertex_normals(v, f), [1, 5, 10], 0.5)
    assert_allclose(data[paths.expression("e1", "reconstruction_rms_mm")], split.total_mm)
    assert_allclose(data[paths.expression("e1", "reconstruction_normal_rms_mm")], split.normal_mm)
    assert_allclose(
        data[paths.expression("e1", "reconstruction_tangential_rms_mm")], split.tangential_mm
    )
    rms = np.sqrt(np.mean(np.sum(field**2, axis=1)))
    assert rms < 0.5  # the field moves the cap less than the target: no mode is needed
    assert data[paths.expression("e1", "modes_to_target")] == 0.0
    assert float(data[paths.modal("reconstruction_target_mm")]) == 0.5


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
        solve_modes(k, m, fixed, 2, SolverOptions(method="lobpcg"))
    with pytest.raises(InputError, match="fixed_dofs"):
        solve_modes(k, m, [k.shape[0]], 2)
    with pytest.raises(InputError, match="square"):
        solve_modes(k[:, :-1], m, fixed, 2)
    with pytest.raises(InputError, match="components"):
        fixed_dofs(boundary_vertices(f), "drilling")
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
