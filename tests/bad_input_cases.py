"""Bad input for HTPPC, run under ``mpiexec -n 1`` or ``-n 2`` (``-n 3`` for
``decoupled_rank``) by tests/test_bad_input.py.

Every case builds its matrix on every rank, solves with CG + HTPPC as it comes (plus the case's options)
and prints one line per rank: ``CASE <name> rank <r>: <outcome>`` with the outcome ``error: <message>``,
``converged <its> <relres> <analyses> <numeric steps>`` or ``diverged <PETSc reason>``.
"""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.bench.harness import reason_name  # noqa: E402
from petsc_htp.petscmat import region_nullspace  # noqa: E402
from petsc_htp.scenes.foreign import cubes, dmda, neumann  # noqa: E402
from petsc_htp.scenes.generator import make_frame  # noqa: E402

COMM = PETSc.COMM_WORLD
N = 1024
BASE = make_frame(N, seed=1_000_000)


def dist(A, null=None, rows_on=None, symmetric=True):
    """A distributed AIJ copy of the global scipy ``A`` (``rows_on``: rows per rank; default PETSc's split)."""
    A = sp.csr_matrix(A)
    size, rank = COMM.getSize(), COMM.getRank()
    counts = rows_on or [A.shape[0] // size + (r < A.shape[0] % size) for r in range(size)]
    start = sum(counts[:rank])
    local = A[start:start + counts[rank]]
    mat = PETSc.Mat().createAIJ(size=((counts[rank], A.shape[0]), (counts[rank], A.shape[1])), comm=COMM,
                                nnz=(np.diff(local.indptr).astype(PETSc.IntType), np.diff(local.indptr).astype(PETSc.IntType)))
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    for i in range(local.shape[0]):
        lo, hi = local.indptr[i], local.indptr[i + 1]
        mat.setValues(start + i, local.indices[lo:hi].astype(PETSc.IntType), local.data[lo:hi])
    mat.assemble()
    if null is not None:
        mat.setNullSpace(region_nullspace(mat, null))
    if symmetric:
        mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat


def htp_ksp(prefix, comm=COMM):
    """A KSP under ``prefix`` whose options (set in the database) are CG to 1e-8 in the unpreconditioned norm with
    HTPPC; KSPSetFromOptions is the caller's."""
    db = PETSc.Options(prefix)
    for k, v in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "pc_type": "python",
                 "pc_python_type": "petsc_htp.HTPPC"}.items():
        db.setValue(k, v)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    return ksp


def rhs(mat, b):
    vec = mat.createVecLeft()
    lo, hi = vec.getOwnershipRange()
    vec.setArray(np.asarray(b, dtype=np.float64)[lo:hi])
    return vec


def solve(mat, b, opts=(), ksp=None, pmat=None):
    """(reason, its, relres, ctx) of CG + HTPPC on ``mat`` (a new KSP unless ``ksp``; preconditioned from ``pmat``
    where given)."""
    db = PETSc.Options()
    base = {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 500,
            "pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
    if COMM.getSize() > 1:          # the two-level method: these matrices would be factored whole on every rank
        base["htp_direct_max"] = 0  # (a rank that owns no rows still gets that factor)
    x, bv = mat.createVecRight(), rhs(mat, b)
    x.set(0.0)
    try:
        for k, v in {**base, **dict(opts)}.items():
            db.setValue(k, v)
        fresh = ksp is None
        if fresh:
            ksp = PETSc.KSP().create(COMM)
        ksp.setOperators(mat, mat if pmat is None else pmat)
        if fresh:                               # a second KSPSetFromOptions would make a new python context
            ksp.setFromOptions()
        ksp.solve(bv, x)
    finally:
        for k in {**base, **dict(opts)}:
            db.delValue(k)
    r = bv.duplicate()
    mat.mult(x, r)
    r.aypx(-1.0, bv)
    nsp = mat.getNullSpace()
    if nsp.handle:
        nsp.remove(r)
    return ksp.getConvergedReason(), ksp.getIterationNumber(), r.norm() / bv.norm(), ksp


def outcome(mat, b, opts=(), ksp=None, pmat=None) -> tuple:
    reason, its, relres, ksp = solve(mat, b, opts, ksp, pmat)
    ctx = ksp.getPC().getPythonContext()
    if reason > 0:
        return f"converged {its} {relres:.1e} {ctx.analysis_count} {ctx.numeric_count}", ksp
    return f"diverged {reason_name(reason)}", ksp


def sealed(A, rows):
    """A with every coupling between ``rows`` and the others stored as an explicit zero (a sealed region)."""
    A = sp.csr_matrix(A, copy=True)
    inside = np.zeros(A.shape[0], dtype=bool)
    inside[rows] = True
    r = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    cut = inside[r] != inside[A.indices]
    A.data[cut] = 0.0
    A.data[r == A.indices] = 0.0
    A.data[r == A.indices] = -np.bincount(r[r != A.indices], A.data[r != A.indices], A.shape[0])
    return A


def regions(A):
    from scipy.sparse.csgraph import connected_components

    B = A.multiply(A != 0).tocsr()
    return connected_components(B, directed=False)[1]


def case_nan():
    A = BASE.A.copy()
    A.data[-1] = np.nan                         # the last row: rank 1's on two ranks
    return outcome(dist(A, regions(BASE.A)), BASE.b)[0]


def case_inf():
    A = BASE.A.copy()
    A.data[-3] = np.inf
    return outcome(dist(A, regions(BASE.A)), BASE.b)[0]


def case_empty_row():
    A = BASE.A.tolil()
    A.rows[N - 1], A.data[N - 1] = [], []
    A = sp.csr_matrix(A)
    return outcome(dist(A, symmetric=False), BASE.b)[0]


def case_zero_diagonal():
    return outcome(dist(_set_diag(N - 2, 0.0)), BASE.b)[0]


def _set_diag(i, value):
    A = BASE.A.tolil()
    A[i, i] = value
    return sp.csr_matrix(A)


def case_negative_diagonal():
    return outcome(dist(_set_diag(N - 2, -1.0)), BASE.b)[0]


def case_nonsymmetric():
    A = BASE.A.tolil()
    j = next(c for c in A.rows[5] if c != 5)
    A[5, j] = 3.0 * A[5, j]                     # one coupling three times its mirror
    return outcome(dist(sp.csr_matrix(A), symmetric=False), BASE.b)[0]


def case_dirichlet_columns():
    """Dirichlet rows as MatZeroRows leaves them: rows 0-31 hold just their diagonal, the other rows keep their
    couplings to them (not symmetric, as PETSc's DMDA tutorials assemble it): preconditioned without those columns."""
    A = BASE.A.tolil()
    for i in range(32):
        A.rows[i], A.data[i] = [i], [float(BASE.A[i, i])]
    return outcome(dist(sp.csr_matrix(A), symmetric=False), BASE.b)[0]


def case_indefinite():
    """Symmetric with a positive diagonal but indefinite: every coupling +3 |a_ij| (a checkerboard vector
    has a negative Rayleigh quotient)."""
    A = sp.csr_matrix(BASE.A, copy=True)
    r = np.repeat(np.arange(N), np.diff(A.indptr))
    A.data[r != A.indices] *= -3.0
    return outcome(dist(A), BASE.b)[0]


def case_indefinite_rich():
    """The same with rich rows (A^2, 13-point): on one rank the whole matrix gets ICC(0), whose shift hides the
    negative pivots, so CG's own check names it."""
    A = sp.csr_matrix(BASE.A @ BASE.A)
    r = np.repeat(np.arange(N), np.diff(A.indptr))
    A.data[r != A.indices] *= -3.0
    return outcome(dist(A), BASE.b)[0]


def case_decoupled_rank():
    """Two components, the second (512 rows) decoupled from the first: on 3 ranks the last rank's leaves have no
    coupling to another rank while the others' do (every rank still takes part in the scatter)."""
    A = sp.block_diag([BASE.A, BASE.A[:512, :512]]).tocsr()
    rows_on = [600, 424, 512] if COMM.getSize() == 3 else None
    return outcome(dist(A, rows_on=rows_on), A @ np.linspace(1.0, 2.0, A.shape[0]))[0]


def case_nonsquare():
    mat = PETSc.Mat().createAIJ(size=((None, N), (None, N + 1)), nnz=1, comm=COMM)
    lo, hi = mat.getOwnershipRange()
    for i in range(lo, hi):
        mat.setValue(i, i, 1.0)
    mat.assemble()
    return outcome(mat, np.ones(N))[0]


def case_empty_matrix():
    mat = PETSc.Mat().createAIJ(size=((None, N), (None, N)), nnz=1, comm=COMM)
    mat.assemble()
    return outcome(mat, np.ones(N))[0]


def case_rank_without_rows():
    """Every row on the first rank: on several ranks one factor of the whole matrix, gathered on every rank."""
    rows_on = [N] + [0] * (COMM.getSize() - 1)
    return outcome(dist(BASE.A, regions(BASE.A), rows_on=rows_on), BASE.b)[0]


def case_rank_without_rows_large():
    """A 2-D Laplacian of 9 216 rows (more than one gathered factor serves) on the first rank alone: HTPPC on the
    ranks that own rows (there its banded factor)."""
    side = 96
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    A = sp.kronsum(T, T).tocsr()
    rows_on = [A.shape[0]] + [0] * (COMM.getSize() - 1)
    return outcome(dist(A, rows_on=rows_on), np.ones(A.shape[0]))[0]


def case_rank_without_rows_twolevel():
    """A 2-D Laplacian of 40 000 rows on the first rank alone: HTPPC on the ranks that own rows (PCTELESCOPE moves
    them there; on one rank the multilevel V-cycles)."""
    side = 200
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    A = sp.kronsum(T, T).tocsr()
    rows_on = [A.shape[0]] + [0] * (COMM.getSize() - 1)
    text, ksp = outcome(dist(A, rows_on=rows_on), np.ones(A.shape[0]))
    return f"{text} {getattr(ksp.getPC().getPythonContext().setup, 'kind', 'twolevel')}"


def case_rank_without_rows_indefinite():
    """A 2-D Laplacian of 9 216 rows less 0.5 I (indefinite, positive diagonal) on the first rank alone: the error
    of the HTPPC on the ranks that own rows reaches every rank (the others had gone on and hung)."""
    side = 96
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    A = (sp.kronsum(T, T) - 0.5 * sp.identity(side * side)).tocsr()
    rows_on = [A.shape[0]] + [0] * (COMM.getSize() - 1)
    return outcome(dist(A, rows_on=rows_on), np.ones(A.shape[0]))[0]


def case_fewer_rows_than_ranks():
    """One row per rank but the last, which owns none (a 1 x 1 matrix on two ranks), with a leaf solver option set
    (on several ranks it is the leaves', not the gathered factor's: it had made a sequential ICC on the MPIAIJ)."""
    size = max(COMM.getSize() - 1, 1)
    A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (size, size)).tocsr()
    rows_on = [1] * size + [0] * (COMM.getSize() - size)
    return outcome(dist(A, rows_on=rows_on), np.ones(size), {"htp_leaf_pc_type": "icc"})[0]


def case_explicit_zeros():
    """A sealed region whose couplings to the rest are stored zeros, one null vector per region attached."""
    ix = np.rint(BASE.coords[:, 0] * 32 - 0.5)
    iy = np.rint(BASE.coords[:, 1] * 32 - 0.5)
    A = sealed(BASE.A, np.flatnonzero((ix < 8) & (iy < 8)))
    reg = regions(A)
    b = BASE.b - (np.bincount(reg, BASE.b) / np.bincount(reg))[reg]
    return outcome(dist(A, reg), b)[0]


def _three_regions():
    blocks = [make_frame(256, seed=s).A for s in (1, 2, 3)]
    A = sp.csr_matrix(sp.block_diag(blocks))
    reg = np.repeat(np.arange(3), 256)
    b = np.random.default_rng(0).standard_normal(768)
    return A, reg, b - (np.bincount(reg, b) / 256)[reg]


def case_null_components_attached():
    A, reg, b = _three_regions()
    return outcome(dist(A, reg), b)[0]


def case_null_components_detected():
    A, reg, b = _three_regions()
    return outcome(dist(A), b)[0]


def case_inconsistent_components():
    """Three components, no null space attached, a right-hand side not summing to zero on each: the named error, whose
    advice is one vector per component (the constant alone is not this matrix's null space)."""
    A, reg, b = _three_regions()
    return outcome(dist(A), b + reg)[0]


def case_pattern_change():
    """The same KSP gets a matrix of the same size with more couplings (a new pattern)."""
    out, ksp = outcome(dist(BASE.A, regions(BASE.A)), BASE.b)
    extra = sp.diags([np.full(N - 40, -0.5)], [40], shape=(N, N))
    A = sp.csr_matrix(BASE.A + extra + extra.T + sp.diags(np.asarray(-(extra + extra.T).sum(1)).ravel()))
    return outcome(dist(A, regions(A)), BASE.b, ksp=ksp)[0]


def case_values_only():
    mat = dist(BASE.A, regions(BASE.A))
    _, ksp = outcome(mat, BASE.b)
    mat.scale(3.0)
    return outcome(mat, BASE.b, ksp=ksp)[0]


def case_rescaled_values():
    """New values D A D (D random in 0.5 .. 2) twice on one KSP, a new coarse space each time: the row-scaled piece
    vectors |diag|^-1/2, so W's values change (on two ranks W^T A W once kept the old ones: DIVERGED_ITS)."""
    side = 32
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    mat = dist(sp.kronsum(T, T))
    b, opts = np.ones(side * side), {"htp_coarse_space_every": 1}
    _, ksp = outcome(mat, b, opts)
    rng = np.random.default_rng(5)
    for _ in range(2):
        d = rhs(mat, rng.uniform(0.5, 2.0, side * side))
        mat.diagonalScale(d, d)
        result = outcome(mat, b, opts, ksp=ksp)[0]
    return result


def case_chain():
    """A 1-D Laplacian of 100 000 rows, two-level (as it comes a band Cholesky factor): on two ranks its 16 668 coarse
    rows passed the size where V-cycles replace the LU, which did not solve a chain's coarse operator (5 000
    iterations); a chain keeps the LU."""
    n = 100_000
    A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (n, n)).tocsr()
    return outcome(dist(A), np.random.default_rng(11).standard_normal(n), {"htp_direct_max": 0})[0]


def case_tiny_entries():
    """1e-20 A, A a DMDA program's 2-D matrix of 16 384 rows with coefficient jumps, two-level: PETSc's LU calls
    pivots below 100 eps zero for entries below one; on two ranks the redundant coarse LU's did (DIVERGED_ITS)."""
    A, b = dmda(2, 128, 1e3, 0)
    return outcome(dist(1e-20 * A), b, {"htp_direct_max": 0})[0]


def case_penalty_rows():
    """A Neumann square whose one side is held by penalty rows (a_ii + 4e30, FreeFEM's tgv), two-level: without
    them out of W, CG stopped "converged" at a true residual of 2e-3 (one rank)."""
    side = 96
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side)).tolil()
    T[0, 0] = T[-1, -1] = 1.0
    A = sp.kronsum(T.tocsr(), T.tocsr()).tocsr()
    A = (A + sp.diags((np.arange(side * side) % side == 0) * 4e30)).tocsr()
    return outcome(dist(A), np.random.default_rng(3).standard_normal(side * side), {"htp_direct_max": 0})[0]


def case_singular_scaled():
    """D A D, A the foreign study's Neumann matrix of 4 096 rows (coefficient jumps of 1e3) and D = |diag A|^-1/2,
    nothing attached: singular with D^-1 1, not the constant, as its null vector, so no row sum vanishes; one factor
    of the whole matrix on one rank, whose Cholesky factor had a negative pivot: HTPPC called the matrix indefinite.
    Every component is grounded now where the factor has negative pivots."""
    A, b = neumann(64, 1e3, 0)[:2]
    D = sp.diags(1.0 / np.sqrt(A.diagonal()))
    return outcome(dist(D @ A @ D), D @ b)[0]


def _neumann_square(side=30):
    """The 5-point Neumann Laplacian of side^2 rows (row sums 0, the constant its null vector), nothing attached."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side)).tolil()
    T[0, 0] = T[-1, -1] = 1.0
    return sp.kronsum(T.tocsr(), T.tocsr()).tocsr()


def case_null_vector_attached():
    """D A D, A the Neumann square's Laplacian of 22 500 rows and D = 10^U(-1, 1) per row, its null vector D^-1 1
    attached: the pieces' constants made the coarse space (423 CG iterations), now that vector does."""
    A = _neumann_square(150)
    d = 10 ** np.random.default_rng(2).uniform(-1, 1, A.shape[0])
    mat = dist(sp.diags(d) @ A @ sp.diags(d))
    z = mat.createVecRight()
    lo, hi = z.getOwnershipRange()
    z.setArray(1 / d[lo:hi])
    z.normalize()
    mat.setNullSpace(PETSc.NullSpace().create(vectors=[z], comm=COMM))
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    return outcome(mat, b - (b @ (1 / d)) / ((1 / d) @ (1 / d)) * (1 / d))[0]


def case_null_space_split():
    """The Neumann square's constant attached as a vector split as PETSc splits 900 rows, the matrix's rows split
    600/300 on two ranks: each rank read its own part, one raised, the other waited in a collective (a hang)."""
    size = COMM.getSize()
    mat = dist(_neumann_square(), rows_on=[600, 300] if size == 2 else None)
    z = PETSc.Vec().createMPI(900, comm=COMM)
    z.set(1.0 / 30)
    mat.setNullSpace(PETSc.NullSpace().create(vectors=[z], comm=COMM))
    return outcome(mat, np.sin(np.arange(900.0)) - np.sin(np.arange(900.0)).mean())[0]


def case_coordinates_on_some_ranks():
    """Coordinates attached on the first rank only (one rank: on every rank): the ranks took different collective
    paths and the solve hung."""
    import petsc_htp

    A, b = dmda(2, 64, 1e3, 0)
    mat = dist(A)
    if COMM.getRank() == 0:
        lo, hi = mat.getOwnershipRange()
        grid = np.stack(np.meshgrid(np.arange(64.0), np.arange(64.0), indexing="ij"), -1).reshape(-1, 2)
        petsc_htp.attach(mat, grid[lo:hi])
    return outcome(mat, b)[0]


def case_shuffled_coordinates():
    """Coordinates in another order than the rows: Morton leaves of rows that share no coupling made every row a
    piece of its own and a coarse LU of about N rows (tens of seconds at 10 000 rows); now they are ignored."""
    import petsc_htp

    A, b = dmda(2, 100, 1e3, 0)
    mat = dist(A)
    grid = np.stack(np.meshgrid(np.arange(100.0), np.arange(100.0), indexing="ij"), -1).reshape(-1, 2)
    petsc_htp.attach(mat, grid[np.random.default_rng(0).permutation(10000)])
    text, ksp = outcome(mat, b)
    return f"{text}; {ksp.getPC().getPythonContext().variant.note}"


def case_inconsistent_factor():
    """A singular Neumann matrix without its null space, b not in its range, one factor of the whole matrix (a band
    on one rank, gathered on two): CG reported CONVERGED_RTOL at a true relative residual of 7.6 (16 on two ranks)."""
    return outcome(dist(_neumann_square()), np.random.default_rng(1).standard_normal(900), {"htp_direct_max": -1})[0]


def case_inconsistent_twolevel():
    """The same, two-level (CG stopped with DIVERGED_DTOL): the same named error."""
    return outcome(dist(_neumann_square()), np.random.default_rng(1).standard_normal(900), {"htp_direct_max": 0})[0]


def case_inconsistent_multilevel():
    """The same, the multilevel V-cycles (their shifted coarse LU; CG reported CONVERGED_RTOL at a true relative
    residual of 74 on a 65 536-row Neumann square): the same named error."""
    return outcome(dist(_neumann_square()), np.random.default_rng(1).standard_normal(900),
                   {"htp_variant": "multilevel", "htp_direct_max": 0, "htp_ml_coarse_max": 100})[0]


def case_inconsistent_multilevel_components():
    """A Dirichlet square (the DMDA matrix) beside a floating Neumann square (a second component whose row sums vanish),
    nothing attached, b with a part along the floating square's constant, the multilevel V-cycles: on two ranks the
    whole matrix had been taken as one component, not null, and CG reported CONVERGED_RTOL at a true relative residual
    of 0.39; the components are now found over the ranks."""
    A = sp.block_diag([dmda(2, 40)[0], _neumann_square()]).tocsr()
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    return outcome(dist(A), b, {"htp_variant": "multilevel", "htp_direct_max": 0, "htp_ml_coarse_max": 100})[0]


def case_shifted_to_rounding():
    """I + 1e13 K, K the Neumann square (an implicit heat step at dt = 1e13 h^2): rows that sum to 1e-14 of their
    entries count as summing to zero, and the error says so (GAMG reported CONVERGED_RTOL at a true relative residual
    of 1e-6 on such a matrix)."""
    A = (1e13 * _neumann_square() + sp.identity(900)).tocsr()
    return outcome(dist(A), np.random.default_rng(1).standard_normal(900))[0]


def case_singular_then_regular():
    """One factor of the whole matrix, the same KSP and Mat: the Neumann square (b summing to zero, the constant
    attached), then new values K + 0.1 I (regular, nothing attached) and any b. A projection off the constant kept from the singular values had left the regular
    solve at a true relative residual of 0.04, reported converged."""
    K = _neumann_square()
    mat, b = dist(K), np.random.default_rng(1).standard_normal(900)
    mat.setNullSpace(PETSc.NullSpace().create(constant=True, comm=COMM))      # attached, then taken off
    _, ksp = outcome(mat, b - b.mean(), {"htp_direct_max": -1})
    mat.setNullSpace(PETSc.NullSpace())
    start, end = mat.getOwnershipRange()
    local = sp.csr_matrix(K + 0.1 * sp.identity(900))[start:end]
    for i in range(local.shape[0]):
        lo, hi = local.indptr[i], local.indptr[i + 1]
        mat.setValues(start + i, local.indices[lo:hi].astype(PETSc.IntType), local.data[lo:hi])
    mat.assemble()
    return outcome(mat, b, {"htp_direct_max": -1}, ksp=ksp)[0]


def case_inconsistent_then_attached(errors=1):
    """The inconsistent case's error (``errors`` times), then its advice on the same KSP: the null space attached, the
    same b."""
    mat, b = dist(_neumann_square()), np.random.default_rng(1).standard_normal(900)
    ksp = PETSc.KSP().create(COMM)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8, max_it=500)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonType("petsc_htp.HTPPC")
    for _ in range(errors):
        try:
            outcome(mat, b, {"htp_direct_max": 0}, ksp)
        except PETSc.Error:
            pass
    mat.setNullSpace(PETSc.NullSpace().create(constant=True, comm=COMM))
    return outcome(mat, b, {"htp_direct_max": 0}, ksp)[0]


def case_inconsistent_three_times():
    """Three such errors on one KSP, then the null space attached: PETSc lowers its count of a PC's presolves only in
    PCPostSolve, which a KSPSolve that stops with an error skips, so after two errors every solve of the KSP failed
    with 'Cannot embed PCPreSolve() more than twice' (HTPPC now runs PCPostSolve before it raises)."""
    return case_inconsistent_then_attached(errors=3)


def case_singular_pmat():
    """A regular operator A + 0.01 I preconditioned from the singular Neumann A (nothing attached) and a b outside
    A's range: the solve is well posed, so no error (the check reads the KSP's own operator)."""
    A = _neumann_square()
    return outcome(dist(A + 0.01 * sp.identity(900)), np.random.default_rng(1).standard_normal(900),
                   {"htp_direct_max": 0}, pmat=dist(A))[0]


def case_singular_pmat_multilevel():
    """The same under the multilevel V-cycles, whose input and output are taken off the Pmat's null constants only
    where the solved Amat annihilates them too (else M was singular and CG never reached the constants' part)."""
    A = _neumann_square()
    return outcome(dist(A + 0.01 * sp.identity(900)), np.random.default_rng(1).standard_normal(900),
                   {"htp_variant": "multilevel", "htp_direct_max": 0, "htp_ml_coarse_max": 100}, pmat=dist(A))[0]


def case_second_set_from_options():
    """KSPSetFromOptions again between two solves (petsc4py makes a new python context, which PETSc, holding the PC
    as set up, never set up: 'HTPPC.apply called before setUp')."""
    A, b = dmda(2, 64, 1e3, 0)
    mat = dist(A)
    ksp = outcome(mat, b)[1]
    db = PETSc.Options()
    opts = {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
    for k, v in opts.items():
        db.setValue(k, v)
    try:
        ksp.setFromOptions()
    finally:
        for k in opts:
            db.delValue(k)
    return outcome(mat, b, ksp=ksp)[0]


def case_jumps3d():
    """Cell-centred finite volumes on 44^3 cells, 60 random cubes of 5^3 cells at 1e6, Dirichlet walls: the paired
    leaves' two coarse V-cycles with Chebyshev's bound at 1.1 x the estimated eigenvalue made M indefinite (CG:
    DIVERGED_INDEFINITE_PC after 8 iterations)."""
    A, b = cubes(44)
    return outcome(dist(A), b, {"htp_direct_max": 0})[0]


def case_loose_coarse_cycles():
    """A coarse GAMG that does not coarsen (``-htp_cs_pc_gamg_threshold 0.3``: one level, a smoother) on a 2-D
    Laplacian of 22 500 rows: the deflated form, which takes the V-cycles as exact, ran to DIVERGED_ITS on 2-4 ranks
    (182 iterations on one); the probe's forward error (0.8) now sends it to the balanced form."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (150, 150))
    A = (sp.kron(sp.identity(150), T) + sp.kron(T, sp.identity(150))).tocsr()
    b = np.random.default_rng(4).standard_normal(A.shape[0])
    return outcome(dist(A), b, {"htp_direct_max": 0, "htp_coarse_solver": "gamg",
                                "htp_cs_pc_gamg_threshold": 0.3})[0]


def case_penalty_rows_last():
    """A checkerboard of conductivities 1 and 1e4 (5-point finite volumes, 64^2 cells) whose wall rows are held by a
    penalty of 1e10 and numbered last, as finite element codes number their boundary nodes, on 2 ranks split
    3 796/300: the second rank's rows are mostly the penalty's, so its own median diagonal had been a penalty value and
    none of its rows counted as pinned; they made the scaling's quotients, and the pieces took |diag|^-1/2 (154 CG
    iterations against 30 on one rank). The typical diagonal is now the least over the ranks."""
    from petsc_htp.scenes.gallery import face_weights

    side = 64
    cell = np.add.outer(np.arange(side) * 8 // side, np.arange(side) * 8 // side) % 2
    wx, wy, _ = face_weights(np.where(cell == 0, 1e4, 1.0))
    i = np.arange(side * side).reshape(side, side)
    rows = np.concatenate([i[:, :-1].ravel(), i[:-1, :].ravel()])
    cols = np.concatenate([i[:, 1:].ravel(), i[1:, :].ravel()])
    K = sp.coo_matrix((-np.concatenate([wx.ravel(), wy.ravel()]), (rows, cols)), shape=(side * side,) * 2).tocsr()
    K = K + K.T
    K = (K - sp.diags(np.asarray(K.sum(axis=1)).ravel())).tocsr()
    wall = np.zeros((side, side), dtype=bool)
    wall[0], wall[-1], wall[:, 0], wall[:, -1] = True, True, True, True
    order = np.argsort(wall.ravel(), kind="stable")               # interior first, the walls last
    A = (K + sp.diags(1e10 * wall.ravel())).tocsr()[order][:, order]
    b = np.where(wall.ravel()[order], 0.0, 1.0)
    split = [side * side - 300, 300] if COMM.getSize() == 2 else None
    return outcome(dist(A, rows_on=split), b, {"htp_direct_max": 0})[0]


def case_gathered_lu_asked():
    """PyAMG's 966-row discontinuous Galerkin matrix, whose rich rows take ICC(0) of the whole matrix (gathered on
    every rank of two), with ``-htp_leaf_redundant_pc_type lu``: the positive_definite shift chosen for ICC(0) went to
    the user's LU, and PETSc crashed with SEGV on two ranks. The inner type the user chose takes PETSc's defaults."""
    from petsc_htp.bench.foreigncases import pyamg_cases

    A, b = pyamg_cases()["pyamg_local_disc_galerkin_diffusion"][:2]
    return outcome(dist(A), b, {"htp_direct_max": -1, "htp_leaf_redundant_pc_type": "lu"})[0]


def case_missing_checkpoint():
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b,
                   {"htp_variant": "paper", "htp_checkpoint": "/nonexistent/model.pt"})[0]


def case_corrupt_checkpoint():
    path = Path(sys.argv[1]) / "corrupt.pt"
    if COMM.getRank() == 0:
        path.write_bytes(b"not a torch checkpoint" * 8)
    COMM.barrier()
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b, {"htp_variant": "paper", "htp_checkpoint": str(path)})[0]


def case_unknown_form():
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b, {"htp_form": "banana"})[0]


def case_unknown_coarse():
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b, {"htp_coarse": "fancy"})[0]


def case_vector_layout():
    """A right-hand side whose parts differ from the matrix's rows by 5 entries (the global size alike on several
    ranks): a named error on every rank (it had been PETSc's 'Incompatible vector local lengths' from HTPPC's start)."""
    mat = dist(BASE.A, regions(BASE.A))
    rows = mat.getLocalSize()[0] + (5 if COMM.getRank() == 0 else -5 if COMM.getRank() == 1 else 0)
    b = PETSc.Vec().createMPI((rows, None if COMM.getSize() > 1 else rows), comm=COMM)
    b.set(1.0)
    ksp = PETSc.KSP().create(COMM)
    ksp.setOperators(mat)
    ksp.setType("cg")
    ksp.getPC().setType("python")
    ksp.getPC().setPythonType("petsc_htp.HTPPC")
    ksp.solve(b, mat.createVecRight())
    return "converged"


def case_unknown_coarse_solver():
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b, {"htp_coarse_solver": "mumps"})[0]


def case_unknown_aggregation():
    return outcome(dist(BASE.A, regions(BASE.A)), BASE.b, {"htp_aggregation": "triples"})[0]


def main():
    only = sys.argv[2:]                         # case names to run (default: every case)
    for name, fn in sorted((k, v) for k, v in globals().items() if k.startswith("case_")):
        if only and name[5:] not in only:
            continue
        try:
            text = fn()
        except Exception as exc:  # the case's outcome: the deepest named error (ValueError) of the chain
            chain = [exc]
            while chain[-1].__cause__ is not None:
                chain.append(chain[-1].__cause__)
            named = [e for e in chain if isinstance(e, ValueError)]
            exc = named[-1] if named else chain[-1]
            text = "error: " + (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            if not named:
                text += f" [{type(exc).__name__}]"
        print(f"CASE {name[5:]} rank {COMM.getRank()}: {text}", flush=True)
        COMM.barrier()


if __name__ == "__main__":
    main()
