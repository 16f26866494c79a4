"""Natural modes of a finite element model: the generalised eigenproblem ``K q = omega^2 M q``.

The lowest ``k`` modes are found by shift-invert at ``sigma = 0`` on the free-DOF submatrices:
the operator ``T = K^-1 M`` (self-adjoint in the M inner product) has its largest eigenvalues
``theta = 1 / omega^2`` at the lowest frequencies. ``K`` is factorised once with SuperLU
(symmetric mode, minimum-degree ordering on ``K + K^T``, no pivoting: ``K`` is positive
definite once the boundary is fixed) after a symmetric diagonal scaling that equalises
translation and rotation rows.

The default solver (``method="block"``) is a thick-restart block Lanczos (block Krylov-Schur)
iteration with full M-reorthogonalisation. It spends its time in two places: triangular solves
with the factor, done a block of right-hand sides at a time (SuperLU's multi-column solves cost
about a third per column of single-vector solves, and the columns are split over two threads,
SuperLU releasing the GIL), and the reorthogonalisation GEMMs. ``method="arpack"`` runs
:func:`scipy.sparse.linalg.eigsh` in shift-invert mode (``mode="normal"``) with the same
factorisation, one vector at a time; ``method="dense"`` solves the dense pencil with LAPACK
(small models, and the block solver hands over to it below ``_DENSE_MAX_DOF`` free DOFs).
Measured on a face-sized curved shell of 60,000 DOF (``benchmarks/bench_modal.py``, two
cores, one BLAS thread): 100 modes in about 7-8 s for the block solver against 13 s for
ARPACK, both to a relative residual below 1e-10; the paper needed about 5 min for 15,000 DOF.
CPU time of assembly and 100 modes on one thread (what an idle core takes; fastest of three,
on a shared machine): the paper's steel shell on 10,000 vertices (60,000 DOF) 8-10 s; the
``skin`` preset's membrane (translations only) on the same mesh (30,000 DOF) about 4 s (11 s
as a soft shell of 60,000 DOF) and on 20,000 vertices (60,000 DOF) 8-10 s.

The mass matrix of a shell is only semi-definite (the drilling rotation has no inertia), so
``M^-1`` is never formed: every vector the iteration produces lies in the range of ``T``, on
which the M inner product is definite.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError
from scan2morph.modal import fem

_METHODS = ("block", "arpack", "dense")
#: Fewest right-hand sides per thread worth a thread of its own.
_MIN_COLS_PER_THREAD = 2
#: Free-DOF count up to which ``method="block"`` hands over to the dense solver.
_DENSE_MAX_DOF = 1500


@dataclass(frozen=True)
class SolverOptions:
    """How :func:`solve_modes` solves (not what: the model is K, M and the fixed DOFs).

    Attributes
    ----------
    options : SolverOptions, optional
        Method, tolerance, block and basis sizes, threads, seed and shift; default
        :class:`SolverOptions()`.
    """

    method: str = "block"
    tol: float = 1e-12
    block_size: int | None = None
    max_basis: int | None = None
    threads: int = 2
    seed: int = 0
    shift: float = 0.0


def solve_modes(
    K: sp.spmatrix,
    M: sp.spmatrix,
    fixed_dofs: ArrayLike,
    k: int = 100,
    options: SolverOptions | None = None,
    source: str = "modal",
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lowest natural frequencies and mass-orthonormal mode shapes.

    Parameters
    ----------
    K : (n, n) sparse, symmetric
        Stiffness matrix (N/mm in the mm / N / tonne unit system).
    M : (n, n) sparse, symmetric positive semi-definite
        Mass matrix (tonne).
    fixed_dofs : (m,) int
        Constrained DOF indices (their mode entries are zero).
    k : int
        Number of modes, 1 <= k < number of free DOFs.
    method : {"block", "arpack", "dense"}
        Eigensolver, see the module notes.
    tol : float
        Convergence tolerance on the relative residual of ``T x = theta x`` in the M norm
        (``block``; ``arpack`` uses it as its ``tol``).
    block_size : int, optional
        Block width for ``method="block"``; default ``clip(k // 12, 4, 12)``.
    max_basis : int, optional
        Krylov basis size at which ``method="block"`` thick-restarts (keeping ``k + 2 b``
        Ritz vectors); default ``max(4 k, k + 8 b)``. Memory is about ``16 n max_basis``
        bytes.
    threads : int
        Threads sharing the triangular solves of a block (SuperLU releases the GIL). BLAS
        threads are set by the environment (``OPENBLAS_NUM_THREADS``); with two cores,
        ``threads=2`` and one BLAS thread is the fastest setting measured
        (``benchmarks/bench_modal.py``).
    seed : int
        Seed of the random start block.
    shift : float
        ``s >= 0``: the pencil ``(K + s M, M)`` is solved instead, which has the same modes
        and eigenvalues ``omega^2 + s``; a free (unsupported) shell, whose K is singular
        (rigid-body motion), needs ``s > 0``. Units of ``omega^2``, 1/s^2.
    source : str
        Label for error messages.

    Returns
    -------
    frequencies_hz : (k,) float, ascending
        ``sqrt(lambda) / (2 pi)``, Hz when K and M use mm / N / tonne.
    modes : (n, k) float
        Mode shapes as columns, ``modes.T @ M @ modes = I``, zero at the fixed DOFs.

    Raises
    ------
    InputError
        Non-square or mismatched matrices, fixed DOFs out of range, k out of range, a free DOF
        with no stiffness, or a stiffness matrix that is singular on the free DOFs (a part of
        the model that the fixed DOFs do not hold).
    """
    opt = options or SolverOptions()
    method, tol, seed = opt.method, opt.tol, opt.seed
    if method not in _METHODS:
        raise InputError(source, f"method: expected one of {_METHODS}, got {method!r}")
    n = K.shape[0]
    free, kf, mf, ks = _free_system(K, M, fixed_dofs, k, opt.shift, source)
    if method == "dense" or (method == "block" and free.size <= _DENSE_MAX_DOF):
        lam, xf = _dense(ks, mf, k, source)
    else:
        op = _ShiftInvert(ks, mf, source, opt.threads)
        if method == "arpack":
            lam, xf = _arpack(op, k, tol, seed)
        else:
            b = int(np.clip(k // 12, 4, 12)) if opt.block_size is None else int(opt.block_size)
            if b < 1:
                raise InputError(source, f"block_size: expected a positive integer, got {b}")
            lam, xf = _block_krylov_schur(op, k, b, tol, seed, source, opt.max_basis)
    # Rayleigh quotients (more accurate than 1/theta) and exact M-orthonormalisation.
    xf = _loewdin(xf, mf @ xf)
    lam = np.einsum("ij,ij->j", xf, kf @ xf)
    order = np.argsort(lam)
    lam, xf = lam[order], xf[:, order]
    modes = np.zeros((n, k))
    modes[free] = xf
    return np.sqrt(np.maximum(lam, 0.0)) / (2.0 * np.pi), modes


def _free_system(K, M, fixed_dofs, k: int, shift: float, source: str):
    """The free DOFs, K and M on them and the shifted stiffness ``K + shift M``, checked (the
    errors :func:`solve_modes` lists)."""
    n = K.shape[0]
    if K.shape != (n, n) or M.shape != (n, n):
        raise InputError(
            source, f"K, M: expected two square matrices of one size, got {K.shape}, {M.shape}"
        )
    fixed = np.unique(np.asarray(fixed_dofs, dtype=np.int64))
    if fixed.size and (fixed[0] < 0 or fixed[-1] >= n):
        raise InputError(source, f"fixed_dofs: expected indices in [0, {n - 1}]")
    free = np.setdiff1d(np.arange(n), fixed)
    if not (isinstance(k, int | np.integer) and 1 <= k < free.size):
        raise InputError(
            source, f"k: expected an integer in [1, {free.size - 1}] (free DOFs - 1), got {k}"
        )
    if free.size == n:  # nothing fixed: no copies
        kf, mf = sp.csc_matrix(K), sp.csc_matrix(M)
    else:
        kf = sp.csc_matrix(K)[free][:, free].tocsc()
        mf = sp.csc_matrix(M)[free][:, free].tocsc()
    if not (np.isfinite(shift) and shift >= 0):
        raise InputError(source, f"shift: expected a number >= 0, got {shift}")
    ks = (kf + float(shift) * mf).tocsc() if shift else kf
    diag = ks.diagonal()
    bad = np.flatnonzero(~(diag > 0))
    if bad.size:
        dof = free[bad[0]]
        raise InputError(
            source,
            f"K: free DOF {dof} (vertex {dof // fem.DOF}, component {dof % fem.DOF}) has no "
            "stiffness; fix it or remove the vertex",
        )
    return free, kf, mf, ks


class _ShiftInvert:
    """``T = K^-1 M`` on the free DOFs with one scaled SuperLU factorisation of K."""

    def __init__(self, kf: sp.csc_matrix, mf: sp.csc_matrix, source: str, threads: int = 1):
        self.n = kf.shape[0]
        self.threads = max(1, int(threads))
        self.m = mf
        # Rows of M with mass: M is positive semi-definite, so a zero diagonal entry means a
        # zero row and column (a massless rotation): M-inner products need only these rows.
        self.rows = np.flatnonzero(mf.diagonal() > 0)
        self.m_rows = mf[self.rows][:, self.rows].tocsc()
        self.d = 1.0 / np.sqrt(kf.diagonal())
        ks = kf.tocoo()
        ks.data = ks.data * self.d[ks.row] * self.d[ks.col]
        try:
            self.lu = sla.splu(
                ks.tocsc(),
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise InputError(
                source,
                f"K: singular on the free DOFs ({exc}); some part of the mesh is not held by "
                "the fixed boundary",
            ) from exc
        piv = self.lu.U.diagonal()
        if not np.all(piv > 1e-13 * np.abs(piv).max()):
            raise InputError(
                source,
                "K: not positive definite on the free DOFs (a part of the mesh is not held by "
                "the fixed boundary, or the mesh folds onto itself)",
            )

    def solve_mass(self, m_rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``K^-1 y`` for a right-hand side ``y`` given on the massive rows only (zero
        elsewhere, as every ``M x`` is): (r, b) in, (n, b) out."""
        if self.rows.size == self.n:
            return self.solve_k(m_rhs)
        rhs = np.zeros((self.n, m_rhs.shape[1]), order="F")
        rhs[self.rows] = m_rhs
        return self.solve_k(rhs)

    def solve_k(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``K^-1 rhs`` for (n,) or (n, b) right-hand sides.

        Blocks are split over ``threads`` threads (SuperLU's triangular solves release the GIL
        and share the factor read-only).
        """
        if rhs.ndim == 1:
            return self.d * self.lu.solve(self.d * rhs)
        d = self.d[:, None]
        scaled = np.asfortranarray(d * rhs)
        nb = rhs.shape[1]
        n_threads = min(self.threads, nb // _MIN_COLS_PER_THREAD)
        if n_threads < 2:
            return d * self.lu.solve(scaled)
        cuts = np.linspace(0, nb, n_threads + 1).astype(int)
        parts = [scaled[:, a:z] for a, z in zip(cuts[:-1], cuts[1:], strict=True)]
        with ThreadPoolExecutor(len(parts)) as pool:
            out = list(pool.map(self.lu.solve, parts))
        return d * np.hstack(out)


def _dense(kf, mf, k, source):
    """All modes of the dense pencil via ``eigh(M, K)`` (K definite, M semi-definite)."""
    kd = kf.toarray()
    try:
        mu, x = la.eigh(mf.toarray(), kd, subset_by_index=[kf.shape[0] - k, kf.shape[0] - 1])
    except la.LinAlgError as exc:
        raise InputError(
            source, "K: not positive definite on the free DOFs; some part is not held"
        ) from exc
    if not np.all(mu > 1e-14 * mu.max()):
        raise InputError(source, f"k: asked for {k} modes, more than the model's massive DOFs")
    return 1.0 / mu, x / np.sqrt(mu)


def _arpack(op: _ShiftInvert, k: int, tol: float, seed: int):
    opinv = sla.LinearOperator((op.n, op.n), matvec=op.solve_k, dtype=np.float64)
    v0 = np.random.default_rng(seed).standard_normal(op.n)
    lam, x = sla.eigsh(
        sp.eye(op.n, format="csc"),  # unused: OPinv and M define the shift-invert operator
        k=k,
        M=op.m,
        sigma=0.0,
        which="LM",
        mode="normal",
        OPinv=opinv,
        tol=tol,
        v0=op.solve_k(op.m @ v0),
    )
    return lam, x


def _loewdin(x, mx):
    """``x G^-1/2`` with ``G = x^T M x``: M-orthonormal and closest to ``x`` (no mixing)."""
    g = x.T @ mx
    w, u = np.linalg.eigh(0.5 * (g + g.T))
    return x @ ((u / np.sqrt(w)) @ u.T)


def _m_orthonormalise(x, xr, mxr, drop: float):
    """SVQB: M-orthonormal basis of span(x), dropping directions below ``drop`` of the largest.

    ``xr`` is ``x`` on the massive rows and ``mxr = M x`` there (M is zero elsewhere). Returns
    ``x``, ``M x`` on the massive rows and the (r, b) coefficients ``R`` with ``x_in = x_out R``
    on the kept directions.
    """
    g = xr.T @ mxr
    g = 0.5 * (g + g.T)
    w, u = np.linalg.eigh(g)
    keep = w > drop * max(w[-1], 0.0)
    w, u = w[keep], u[:, keep]
    z = u / np.sqrt(w)
    return x @ z, mxr @ z, (u * np.sqrt(w)).T


def _block_krylov_schur(
    op: _ShiftInvert,
    k: int,
    b: int,
    tol: float,
    seed: int,
    source: str,
    max_dim: int | None = None,
):
    """Largest k eigenpairs of T = K^-1 M by thick-restart block Lanczos (M inner product).

    Each new block is M-orthogonalised in two passes: first against the blocks the Lanczos
    recurrence couples it to (the two latest, or after a restart the kept Ritz vectors and
    the pending block), then against the whole basis (full reorthogonalisation, which keeps
    the basis M-orthonormal to rounding and the Ritz values free of ghosts). The
    Rayleigh-Ritz matrix ``h``
    collects the coefficients, so ``K`` is never applied; the residual of a Ritz pair is the
    norm of its coupling to the pending block. ``M`` times the basis is kept on the massive
    rows only (half the rows of a shell without rotary inertia), which is all the M inner
    products read.
    """
    n = op.n
    if max_dim is None:
        max_dim = max(4 * k, k + 8 * b)
    max_dim = max(min(n - b, max_dim), k + 2 * b)
    keep_dim = min(k + 2 * b, max_dim - 2 * b)
    eps = np.finfo(np.float64).eps
    cap = max_dim + b
    rows = slice(None) if op.rows.size == n else op.rows
    s = np.empty((n, cap), order="F")  # M-orthonormal basis
    ms = np.empty((op.rows.size, cap), order="F")  # M @ basis on the massive rows
    h = np.zeros((cap, cap))  # T s[:, :m] = s[:, :m + r] h[:m + r, :m]

    def put(lo, vec, mvec):
        s[:, lo : lo + vec.shape[1]] = vec
        ms[:, lo : lo + vec.shape[1]] = mvec

    def orthonormal(x, drop):
        return _m_orthonormalise(x, x[rows], op.m_rows @ x[rows], drop)

    start = op.solve_k(op.m @ np.random.default_rng(seed).standard_normal((n, b)))
    v, mv, _ = orthonormal(start, 1e-12)
    r = v.shape[1]
    put(0, v, mv)
    m = 0  # columns whose T image is in h; columns m .. m + r - 1 are the pending block
    local = [(0, r)]  # (first column, width) of the blocks the recurrence couples
    for _ in range(20 * (n // b + 1)):
        w = op.solve_mass(ms[:, m : m + r])
        top = m + r
        coef = np.zeros((top, r))
        for lo, nb in local:  # pass 1: the Lanczos recurrence
            c = ms[:, lo : lo + nb].T @ w[rows]
            w -= s[:, lo : lo + nb] @ c
            coef[lo : lo + nb] += c
        c = ms[:, :top].T @ w[rows]  # pass 2: the whole basis
        w -= s[:, :top] @ c
        coef += c
        v, mv, rcoef = orthonormal(w, 1e3 * eps)
        h[:top, m:top] = coef
        r_new = v.shape[1]
        h[top : top + r_new, m:top] = rcoef
        local = [local[-1], (top, r_new)]
        m, r = top, r_new
        put(m, v, mv)
        if m < k:
            continue
        theta, y = np.linalg.eigh(0.5 * (h[:m, :m] + h[:m, :m].T))
        theta, y = theta[::-1], y[:, ::-1]
        resid = np.linalg.norm(h[m : m + r, :m] @ y[:, :k], axis=0)
        if np.all(resid <= tol * theta[:k]):
            return 1.0 / theta[:k], s[:, :m] @ y[:, :k]
        if r == 0:
            raise InputError(source, f"k: the Krylov space closed at {m} < {k} modes")
        if m + 2 * r > max_dim:
            # Thick restart: keep the leading Ritz vectors and the pending block.
            p = min(keep_dim, m)
            yp = y[:, :p]
            coupling = h[m : m + r, :m] @ yp
            pending, mpending = s[:, m : m + r].copy(), ms[:, m : m + r].copy()
            put(0, s[:, :m] @ yp, ms[:, :m] @ yp)
            put(p, pending, mpending)
            h[:] = 0.0
            h[np.arange(p), np.arange(p)] = theta[:p]
            h[p : p + r, :p] = coupling
            m = p
            local = [(0, p + r)]
    raise InputError(source, f"eigensolver: no convergence of {k} modes to tol {tol:g}")
