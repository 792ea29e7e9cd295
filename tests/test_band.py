"""The banded Cholesky factor (petsc_htp.twolevel.band): as a PETSc PC of its own, and as HTPPC's factor of the
whole matrix where the reverse Cuthill-McKee bandwidth is small (sizing.BAND_WIDTH, one rank)."""
import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

from petsc_htp.scenes import foreign
from petsc_htp.twolevel import nullspace, sizing
from petsc_htp.twolevel.band import Band, ordering, own_width
from test_foreign import lines, solve


def _ksp(A, ksp_type, prefix):
    """A KSP of ``ksp_type`` with BandPC by its options under ``prefix`` on the AIJ copy of ``A``."""
    db = PETSc.Options(prefix)
    for k, v in {"ksp_type": ksp_type, "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 50,
                 "pc_type": "python", "pc_python_type": "petsc_htp.twolevel.band.BandPC"}.items():
        db.setValue(k, v)
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                              A.data), comm=PETSc.COMM_SELF)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    return ksp, mat


@pytest.mark.parametrize("ksp_type", ["cg", "gmres", "minres"])
def test_band_pc_solves_in_one_iteration_and_keeps_its_order_for_new_values(ksp_type):
    """Any KSP: one iteration to 1e-8 on a DMDA-style matrix numbered at random; new values of the same pattern keep
    the order (the same Band), a new pattern makes a new one."""
    A, b = foreign.dmda(2, 40, 1e3, 0)
    p = np.random.default_rng(0).permutation(A.shape[0])
    A, b = sp.csr_matrix(A[p][:, p]), b[p]
    A.sort_indices()
    ksp, mat = _ksp(A, ksp_type, f"band_{ksp_type}_")
    x, rhs = mat.createVecs()
    rhs.setArray(b)
    ksp.solve(rhs, x)
    ctx = ksp.getPC().getPythonContext()
    relres = np.linalg.norm(b - A @ x.getArray()) / np.linalg.norm(b)
    assert ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 1 and relres <= 1e-8
    assert ctx.band.width <= 45 and ctx.band.width == ordering(A)[3]
    band = ctx.band
    mat.scale(2.0)
    ksp.setOperators(mat, mat)
    ksp.solve(rhs, x)
    assert ctx.band is band and np.linalg.norm(b - 2 * A @ x.getArray()) <= 1e-8 * np.linalg.norm(b)
    q = np.random.default_rng(1).permutation(A.shape[0])     # the same size, another pattern
    B = sp.csr_matrix(A[q][:, q])
    B.sort_indices()
    mat2 = PETSc.Mat().createAIJ(B.shape, csr=(B.indptr.astype(PETSc.IntType), B.indices.astype(PETSc.IntType),
                                               B.data), comm=PETSc.COMM_SELF)
    ksp.setOperators(mat2, mat2)
    ksp.solve(rhs, x)
    assert ctx.band is not band and ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 1


def test_band_pc_names_an_indefinite_matrix():
    """A pivot that is not positive is an error that says so (PETSc.Error with the cause attached)."""
    A = sp.diags([np.ones(99), np.r_[2.0 * np.ones(50), -2.0 * np.ones(50)], np.ones(99)], [-1, 0, 1]).tocsr()
    ksp, mat = _ksp(A, "cg", "band_bad_")
    x, rhs = mat.createVecs()
    rhs.set(1.0)
    with pytest.raises(PETSc.Error) as err:
        ksp.solve(rhs, x)
    assert "not positive semidefinite" in str(err.value.__cause__ or err.value)


def test_band_factors_the_lower_triangle_in_its_order_and_grounds_a_null_pivot():
    """Band.solve is A^-1 to rounding; a singular matrix (a Neumann matrix, nothing grounded before) has its null
    pivot grounded, and the grounded factor solves a consistent system exactly; a negative pivot is info > 0."""
    A, _ = foreign.neumann(20)
    A = sp.csr_matrix(A)
    band = Band(A)
    info, grounded = band.factor(A.data)
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    b -= b.mean()
    x = np.empty_like(b)
    band.solve(b, x)
    assert info == 0 and grounded.size == 1 and np.linalg.norm(A @ x - b) <= 1e-8 * np.linalg.norm(b)
    shifted = (A + sp.identity(A.shape[0])).tocsr()
    shifted.sort_indices()
    band = Band(shifted)
    assert band.factor(shifted.data)[0] == 0 and band.factor(shifted.data)[1].size == 0
    band.solve(b, x)
    assert np.linalg.norm(shifted @ x - b) <= 1e-12 * np.linalg.norm(b)
    indefinite = (A - 0.5 * sp.identity(A.shape[0])).tocsr()
    indefinite.sort_indices()
    assert Band(indefinite).factor(indefinite.data)[0] > 0


def test_a_strip_and_a_small_grid_take_the_banded_factor_and_a_wide_grid_does_not():
    """HTPPC as it comes: a strip of 16 x 3 000 cells numbered across (48 000 rows, far above the small sizes; its own
    order), one of 16 x 1 250 numbered along (20 000 rows: reverse Cuthill-McKee's order) and a 2-D DMDA matrix of
    10 000 rows get one banded Cholesky factor, one iteration, and -ksp_view names the order and the bandwidth; a 2-D
    grid whose bandwidth passes sizing.BAND_WIDTH keeps the two-level method, and so does the strip of 48 000 rows
    numbered along (past sizing.BAND_RCM_MAX only the rows' own order is tried; the band may be its coarsest
    level's solve)."""
    def line(k):
        return sp.diags([-np.ones(k - 1), 2 * np.ones(k), -np.ones(k - 1)], [-1, 0, 1])

    across, along = sp.kronsum(line(16), line(3000)).tocsr(), sp.kronsum(line(1250), line(16)).tocsr()
    square, b = foreign.dmda(2, 100, 1e3, 0)
    for A, rhs, order in ((across, np.ones(across.shape[0]), "its own order has bandwidth 16"),
                          (along, np.ones(along.shape[0]), "its reverse Cuthill-McKee order has bandwidth 1"),
                          (sp.csr_matrix(square), b, "bandwidth 100")):
        reason, its, relres, ksp, _ = solve(A, rhs)
        assert reason > 0 and its <= 1 and relres <= 1e-8, (its, relres)
        assert "one banded Cholesky factor" in lines(ksp) and order in lines(ksp), lines(ksp)
    long_along = sp.kronsum(line(3000), line(16)).tocsr()
    reason, its, relres, ksp, _ = solve(long_along, np.ones(long_along.shape[0]))
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp) and "one banded" not in lines(ksp)
    wide, b = foreign.dmda(2, sizing.BAND_WIDTH + 20, 1e3, 0)
    reason, its, relres, ksp, _ = solve(wide, b)
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp) and "one banded" not in lines(ksp)


def test_a_null_direction_that_is_no_constant_is_grounded():
    """D A D of a Neumann matrix (D from 1e-2 to 1e2) with nothing attached: its row sums do not vanish, so no
    component is grounded first; the banded factor's vanishing pivot shows the null direction and is grounded, and CG
    on the consistent system converges."""
    A, _ = foreign.neumann(30)
    d = 10.0 ** np.random.default_rng(0).uniform(-2, 2, A.shape[0])
    S = sp.csr_matrix(sp.diags(d) @ A @ sp.diags(d))
    b = S @ np.random.default_rng(1).standard_normal(A.shape[0])
    reason, its, relres, ksp, _ = solve(S, b)
    assert reason > 0 and relres <= 1e-8 and its <= 5, (reason, its, relres)
    assert "one banded Cholesky factor" in lines(ksp) and "1 null pivot(s) grounded" in lines(ksp)


def _edges(side, sigma):
    """A grid of ``side``^2 cells whose edges have log-normal weights exp(``sigma`` N(0, 1)), Dirichlet walls (1 added
    to the diagonal of the boundary cells): a nonsingular M-matrix."""
    rng = np.random.default_rng(0)
    cell = np.arange(side * side).reshape(side, side)
    a = np.concatenate([cell[:, :-1].ravel(), cell[:-1, :].ravel()])
    c = np.concatenate([cell[:, 1:].ravel(), cell[1:, :].ravel()])
    w = np.exp(sigma * rng.standard_normal(a.size))
    L = sp.csr_matrix((np.concatenate([-w, -w, w, w]), (np.concatenate([a, c, a, c]), np.concatenate([c, a, a, c]))),
                      shape=(side * side,) * 2)
    wall = np.isin(np.arange(side), (0, side - 1))
    A = sp.csr_matrix(L + sp.diags((wall[:, None] | wall[None, :]).ravel().astype(float)))
    A.sort_indices()
    return A, rng.standard_normal(side * side)


def test_a_regular_m_matrix_whose_couplings_span_many_orders_keeps_its_small_pivots():
    """Edge weights exp(7 N(0, 1)) on 100^2 cells: the row sums vanish against the largest diagonal entry, yet the
    signs and the walls' row sums show the matrix regular (nullspace.m_regular), so nothing is grounded and the banded
    factor serves as it is: CG stops after at most 2 iterations at the matrix's precision (PETSc's Cholesky reaches
    6.5e-7; grounded, 354 iterations: results/robust-20261128/edges.txt). A Neumann matrix, its D A D, one with a
    positive coupling and one whose row sums fall 1e-13 of their size below zero (beyond rounding) are not taken for
    regular. Where LAPACK stops at a pivot of zero (w + 1 stored as w = 2^56: a row sum below zero by rounding, taken
    for regular), the row is grounded as before, and the factor is complete."""
    A, b = _edges(100, 7.0)
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                              A.data), comm=PETSc.COMM_SELF)
    reason, its, relres, ksp, _ = solve(A, b, mat=mat)
    assert reason > 0 and its <= 2 and relres <= 1e-5, (reason, its, relres)
    assert "one banded Cholesky factor" in lines(ksp) and "grounded" not in lines(ksp), lines(ksp)
    N, _ = foreign.neumann(12)
    d = 10.0 ** np.random.default_rng(0).uniform(-2, 2, N.shape[0])
    positive = sp.csr_matrix(A[:144, :144])
    positive[0, 1] = positive[1, 0] = 1e-3
    short = sp.csr_matrix(sp.diags([-np.ones(99), 2 * np.ones(100), -np.ones(99)], [-1, 0, 1]))
    short[50, 51] = short[51, 50] = -(1 + 1e-13)
    for M, regular in ((A, True), (N, False), (sp.diags(d) @ N @ sp.diags(d), False), (positive, False),
                       (short, False)):
        M = sp.csr_matrix(M)
        assert nullspace.m_regular(M, *reversed(nullspace.graph_components(M))).all() == regular
    w = 2.0 ** 56
    S = sp.csr_matrix(np.array([[w, -w, 0.0], [-w, w + 1.0, -1.0], [0.0, -1.0, 2.0]]))
    assert nullspace.m_regular(S, np.zeros(3, dtype=np.int64), 1).all()
    band = Band(S)
    info, grounded = band.factor(S.data)
    out = np.zeros(3)
    band.solve(np.array([0.0, 0.0, 1.0]), out)
    G = S + sp.diags([0.0, w, 0.0])
    assert info == 0 and list(grounded) == [1] and np.abs(G @ out - [0.0, 0.0, 1.0]).max() <= 1e-12


def test_a_chain_numbered_in_reversed_blocks_takes_the_reverse_cuthill_mckee_order():
    """Its own bandwidth (63) is within the square root of its 4 096 rows, but its rows span 2: RCM's order (width 1)
    serves; a grid numbered row by row, whose rows span twice its width, keeps its own order without the search."""
    n = 4096
    p = np.concatenate([np.arange(k, k + 32)[::-1] for k in range(0, n, 32)])
    chain = sp.csr_matrix(sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tocsr()[p][:, p])
    chain.sort_indices()
    assert own_width(chain) == 63 and ordering(chain)[3] == 1
    grid = sp.csr_matrix(foreign.dmda(2, 64, 1e3, 0)[0])
    grid.sort_indices()
    perm, _, _, width = ordering(grid)
    assert width == own_width(grid) == 64 and np.array_equal(perm, np.arange(grid.shape[0]))


def test_a_singular_chain_on_two_ranks_is_grounded_in_its_band(tmp_path):
    """On several ranks nothing is grounded before the gathered factor (PCREDUNDANT): a Neumann chain's banded factor
    grounds its null pivot itself, and CG with the constant null space attached converges (PETSc's Cholesky took it by
    its nonzero shift before)."""
    from test_foreign import EXAMPLE, HTPPC_FLAGS, _mpirun

    n = 20000
    A = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tolil()
    A[0, 0] = A[n - 1, n - 1] = 1.0
    A = sp.csr_matrix(A)
    b = np.random.default_rng(0).standard_normal(n)
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data),
                                comm=PETSc.COMM_SELF)
    viewer = PETSc.Viewer().createBinary(str(tmp_path / "neumann_chain.petsc"), "w", comm=PETSc.COMM_SELF)
    mat.view(viewer)
    PETSc.Vec().createWithArray(b - b.mean(), comm=PETSc.COMM_SELF).view(viewer)   # a consistent right-hand side
    viewer.destroy()
    proc = _mpirun(2, EXAMPLE.parent / "matrix_file.py", "-f", str(tmp_path / "neumann_chain.petsc"), *HTPPC_FLAGS)
    assert proc.returncode == 0 and "its graph is a chain" in proc.stdout, proc.stdout + proc.stderr
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert "null pivot(s) grounded" in proc.stdout and relres <= 1.01e-8, proc.stdout


def test_many_null_components_are_grounded_at_once():
    """A hundred Neumann chains side by side, scaled by D = powers of 2 (no row sum vanishes, and the null pivots come
    out exactly zero): after a few factorisations the last row of every component is grounded at once, and CG on a
    consistent right-hand side converges; Band.factor on the chains alone does the same."""
    m, k = 200, 100
    chain = sp.diags([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1]).tolil()
    chain[0, 0] = chain[m - 1, m - 1] = 1.0
    A = sp.block_diag([chain] * k).tocsr()
    band = Band(A)
    info, grounded = band.factor(A.data)
    assert info == 0 and grounded.size >= k
    d = 2.0 ** np.random.default_rng(0).integers(-6, 7, A.shape[0])
    S = sp.csr_matrix(sp.diags(d) @ A @ sp.diags(d))
    b = S @ np.random.default_rng(1).standard_normal(A.shape[0])
    reason, its, relres, ksp, _ = solve(S, b)
    assert reason > 0 and relres <= 1e-8 and its <= 5, (reason, its, relres)
    assert "null pivot(s) grounded" in lines(ksp)


def test_rows_given_to_ground_are_grounded_in_the_band_order_of_a_shuffled_matrix():
    """Two Neumann squares in one matrix, its rows shuffled (reverse Cuthill-McKee then reorders them): the rows given,
    one of each square (in the matrix's own numbering), are those grounded, in one factorisation, and the factor then
    solves a consistent system exactly."""
    N = foreign.neumann(20, 1e3, 0)[0]
    A = sp.block_diag([N, 2.0 * N]).tocsr()
    shuffle = np.random.default_rng(0).permutation(A.shape[0])
    A = sp.csr_matrix(A[shuffle][:, shuffle])
    A.sort_indices()
    band = Band(A)
    assert not band.own
    first = np.flatnonzero(shuffle < N.shape[0])                    # the rows of the first square, now
    ground = np.array([first[-1], np.flatnonzero(shuffle >= N.shape[0])[0]])
    info, grounded = band.factor(A.data, ground)
    assert info == 0 and np.array_equal(np.sort(grounded), np.sort(ground))
    x = np.random.default_rng(1).standard_normal(A.shape[0])
    b, y = A @ x, np.empty(A.shape[0])
    band.solve(b, y)
    assert np.linalg.norm(A @ y - b) <= 1e-8 * np.linalg.norm(b)


def test_the_reverse_cuthill_mckee_order_is_scipys():
    """twolevel/cuthill.py's order (PyAMG's compiled search, no scipy.sparse.csgraph) is scipy's, permutation for
    permutation: a DMDA matrix in its own and a shuffled numbering, a Neumann square beside a log-normal one, rows
    alone beside a grid, 200 small components, an empty pattern, asymmetric ones (through scipy's own), a row that
    stores no diagonal (its degree one less) and rows alone only."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee as scipy_rcm

    from petsc_htp.twolevel.cuthill import reverse_cuthill_mckee

    D = foreign.dmda(2, 64, 1e3, 0)[0]
    shuffle = np.random.default_rng(0).permutation(D.shape[0])
    pair = sp.block_diag([foreign.neumann(20, 1e3, 0)[0], foreign.lognormal(30, 1e3, 0)[0]])
    cases = [D, D[shuffle][:, shuffle], pair,
             sp.block_diag([sp.identity(50), D, sp.identity(7)]),
             sp.block_diag([foreign.neumann(5, 1e3, k)[0] for k in range(200)]), sp.csr_matrix((3, 3)),
             sp.csr_matrix(np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]])),
             sp.csr_matrix(np.array([[1.0, 1.0], [0.0, 1.0]])),                  # row 0 out of the seed's reach
             sp.csr_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])),   # a row without diagonal
             sp.identity(1000, format="csr")]
    for A in cases:
        A = sp.csr_matrix(A)
        A.sort_indices()
        assert np.array_equal(reverse_cuthill_mckee(A), scipy_rcm(A, symmetric_mode=True)), A.shape


def test_the_view_names_the_pc_that_runs_and_serves_a_leaf_pc_that_is_no_factor():
    """-htp_leaf_pc_type icc on a matrix chosen for the band: -ksp_view names PETSc's ICC, which runs (its view had
    said 'one banded Cholesky factor (one iteration)'); -htp_leaf_pc_type jacobi under the two-level method: the view
    (its memory line read the leaf PC's factor, which a Jacobi PC has not) no longer raises."""
    A, b = foreign.dmda(2, 40, 1e3, 0)
    reason, its, relres, ksp, _ = solve(sp.csr_matrix(A), b, htp_leaf_pc_type="icc")
    assert reason > 0 and its > 1 and relres <= 1e-8
    assert "PETSc's icc of the whole matrix, as -" in lines(ksp) and "htp_leaf_pc_type asks" in lines(ksp), lines(ksp)
    reason, its, relres, ksp, _ = solve(sp.csr_matrix(A), b, htp_leaf_pc_type="jacobi")   # the whole matrix's too
    assert reason > 0 and "memory: 0 bytes per unknown" in lines(ksp), lines(ksp)
    A, b = foreign.dmda(2, 150, 1e3, 0)
    reason, its, relres, ksp, _ = solve(sp.csr_matrix(A), b, htp_leaf_pc_type="jacobi")
    assert reason > 0 and relres <= 1e-8 and "memory on this rank" in lines(ksp), lines(ksp)
    viewer = PETSc.Viewer().createASCII("/dev/null", comm=PETSc.COMM_SELF)
    ksp.view(viewer)
    viewer.destroy()


@pytest.mark.parametrize("side", [25, 30, 40, 50])
def test_minres_on_a_small_neumann_square_with_its_null_space_attached(side):
    """MINRES with HTPPC's factor of the whole matrix (a Neumann square, the constant attached as null space): one
    iteration to 1e-8. The factor grounds A; the KSP removed the constant from M r, not from r, and MINRES stopped
    with DIVERGED_INDEFINITE_PC at its rounding-level second residual (625, 900, 1 600 and 2 500 rows; PETSc's own
    LU and Cholesky did so at other sizes): M now takes r less its constant part too."""
    import petsc_htp

    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side)).tolil()
    T[0, 0] = T[-1, -1] = 1.0
    A = sp.kronsum(T.tocsr(), T.tocsr()).tocsr()
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
    nsp = PETSc.NullSpace().create(constant=True, comm=PETSc.COMM_SELF)
    mat.setNullSpace(nsp)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(mat)
    ksp.setType("minres")
    ksp.setTolerances(rtol=1e-8)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonContext(petsc_htp.HTPPC())
    x, b = mat.createVecs()
    b.setRandom()                                   # (PETSc's default generator: the failing right-hand sides)
    nsp.remove(b)
    ksp.solve(b, x)
    relres = np.linalg.norm(b.getArray() - A @ x.getArray()) / b.norm()
    assert ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 1 and relres <= 1e-8, relres
    assert ksp.getPC().getPythonContext().setup.whole
    ksp.destroy()
    mat.destroy()


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_small_matrices_reach_the_tolerance_under_other_ksps(ranks):
    """The foreign study's 2-D DMDA matrix (1 024 rows: one factor of the whole matrix, which starts the solve with
    x0 = M b), its Neumann matrix (900 rows, singular, nothing attached: M = P F^-1 P, P off the constant) and
    rotated anisotropy (1 024 rows) and PyAMG's ``bar`` (600 rows; both ICC(0), but an exact factor under Richardson,
    Chebyshev and CGS) converge under BCGSL, Richardson, Chebyshev, CGS, TFQMR, MINRES, GMRES, BiCGStab and CGNE to
    1e-8 in their own norm, 1e-6 in the true one. Before: BCGSL DIVERGED_DTOL on the factor, Richardson DIVERGED_DTOL
    with ICC(0), Chebyshev refused on the Neumann matrix (its eigenvalue estimate's noisy b taken for the solve's),
    CGS diverged there on 2 ranks; on ``bar`` with ICC(0) Chebyshev ended DIVERGED_NANORINF (then a SEGV) and CGS
    DIVERGED_DTOL, as under PETSc's own ICC(0)."""
    import re
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(Path(__file__).parent / "ksps_case.py")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    rows = re.findall(r"KSP (\S+) (\S+) (-?\d+) (\d+) (\S+)", out.stdout)
    assert len(rows) == 36, out.stdout
    bad = [r for r in rows if int(r[2]) <= 0 or float(r[4]) > 1e-6]
    assert not bad, bad


def test_chebyshev_estimates_its_eigenvalues_on_the_exact_factor_it_iterates():
    """Under KSPCHEBYSHEV PyAMG's ``bar`` takes the exact factor in place of ICC(0), and so does its eigenvalue
    estimate (a GMRES of prefix ``esteig_`` on the same PC): new values cost no analysis (that GMRES had taken ICC(0)
    back at each setup, two analyses a solve, the estimate then ICC(0)'s), and Chebyshev takes PETSc's Cholesky's 28
    steps (on ICC(0) itself it ended in NaN after 1 143)."""
    from petsc_htp import HTPPC
    from petsc_htp.bench.foreigncases import pyamg_cases

    A, b = pyamg_cases()["pyamg_bar"]
    A = sp.csr_matrix(A)
    A.sort_indices()
    it = PETSc.IntType
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(it), A.indices.astype(it), A.data), comm=PETSc.COMM_SELF)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(mat)
    ksp.setType("chebyshev")
    ksp.setTolerances(rtol=1e-8, max_it=200)
    ksp.getPC().setType("python")
    ctx = HTPPC()
    ksp.getPC().setPythonContext(ctx)
    x, rhs = mat.createVecs()
    rhs.array[:] = b
    for k in range(3):
        if k:
            mat.scale(1.5)
        x.set(0.0)
        ksp.solve(rhs, x)
        assert ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 30, (k, ksp.getIterationNumber())
        assert ctx.setup.kind == "cholesky" and ctx.analysis_count == 2, (k, ctx.setup.kind, ctx.analysis_count)
    for obj in (ksp, mat, x, rhs):
        obj.destroy()


@pytest.mark.mpi
def test_two_ranks_gather_the_band():
    """On 2 ranks a small 2-D matrix (the foreign study's DMDA matrix, 1 024 rows) gets the banded factor too,
    gathered and factored on each rank by :class:`BandPC` itself (PCREDUNDANT's LU took 2.2 ms of a 3.7 ms solve),
    and the solve ends at its start."""
    import re
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", "2", sys.executable, str(root / "examples" / "matrix_file.py"), "-case",
                          "dmda2d", "-n", "1024", "-ksp_type", "cg", "-ksp_norm_type", "unpreconditioned", "-pc_type",
                          "python", "-pc_python_type", "petsc_htp.HTPPC", "-ksp_view"], cwd=root, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "banded Cholesky (LAPACK dpbtrf)" in out.stdout and "gathered and factored on each of the 2 ranks" in out.stdout
    assert re.search(r"^iterations: 0$", out.stdout, re.M), out.stdout
    assert float(re.search(r"true relative residual .*: (\S+)", out.stdout).group(1)) <= 1e-10


@pytest.mark.parametrize("ksp_type", ["richardson", "cg"])
def test_a_test_against_the_initial_residual_takes_no_start(ksp_type):
    """-ksp_converged_use_initial_residual_norm measures against ||r0||, which the exact factor's start leaves at
    rounding: no start then (Richardson had run to its iteration limit on an exact x)."""
    import petsc_htp

    A, b = foreign.dmda(2, 30, 1e3, 0)
    A = sp.csr_matrix(A)
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
    prefix = f"uir_{ksp_type}_"
    PETSc.Options(prefix).setValue("ksp_converged_use_initial_residual_norm", True)
    try:
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(mat)
        ksp.setType(ksp_type)
        ksp.setTolerances(rtol=1e-8, max_it=100)
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(petsc_htp.HTPPC())
        ksp.setFromOptions()
        x, rhs = mat.createVecs()
        rhs.setArray(b)
        ksp.solve(rhs, x)
    finally:
        PETSc.Options(prefix).delValue("ksp_converged_use_initial_residual_norm")
    assert ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 2, ksp.getConvergedReason()
    assert np.linalg.norm(b - A @ x.getArray()) <= 1e-8 * np.linalg.norm(b)
    ksp.destroy()
    mat.destroy()


def test_the_own_orders_bandwidth_reads_each_rows_ends_where_sorted_and_every_entry_where_not():
    """own_width gives the largest |i - j| over the stored entries, from each row's first and last column where the
    columns are sorted, from every entry where they are not (rows reversed), empty rows and an empty matrix too."""
    rng = np.random.default_rng(3)
    for seed in range(60):
        n = int(rng.integers(1, 50))
        A = sp.random(n, n, density=rng.uniform(0.0, 0.3), format="csr", random_state=seed)
        A = (A + A.T).tocsr()
        A.sort_indices()
        want = int(np.abs(np.repeat(np.arange(n), np.diff(A.indptr)) - A.indices).max()) if A.nnz else 0
        backwards = np.concatenate([A.indices[A.indptr[i]:A.indptr[i + 1]][::-1] for i in range(n)])
        U = sp.csr_matrix((A.data, backwards.astype(A.indices.dtype), A.indptr), shape=A.shape)
        assert own_width(A) == want and own_width(U) == want, seed
