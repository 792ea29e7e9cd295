"""Matrices from other programs: aggregation leaves, decoupled rows, what the graph shows, small matrices solved
directly, leaves made anew when the couplings move, and the benchmark's foreign study."""
import itertools
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

from petsc_htp.bench import main, store
from petsc_htp.bench.foreigncases import CASES, pyamg_cases
from petsc_htp.bench.studies.foreign import bare_frame
from petsc_htp.petscmat import frame_mat, frame_vec
from petsc_htp.scenes import foreign, meshes
from petsc_htp.twolevel import sizing
from petsc_htp.twolevel.aggregation import DECOUPLED_LEAF, THETA, aggregates, decoupled_rows, sampled_shares, threshold
from petsc_htp.twolevel.graphshape import graph_shape
from petsc_htp.twolevel.leaves import choose_leaves
from petsc_htp.twolevel.structure import WEAK_ROWS

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "dmda_poisson.py"

_PREFIXES = itertools.count()


def solve(A, b, ksp_type="cg", mat=None, ksp=None, **opts):
    """HTPPC as it comes on ``A`` (null space attached where A's row sums vanish) under a fresh prefix, or on the
    given ``ksp``; (reason, iterations, true relres, ksp, mat)."""
    mat = mat or frame_mat(bare_frame(A, b, ""), PETSc.COMM_SELF)
    if ksp is None:
        prefix = f"fo{next(_PREFIXES)}_"
        db = PETSc.Options(prefix)
        for k, v in {"ksp_type": ksp_type, "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8,
                     "ksp_max_it": 500, "pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", **opts}.items():
            db.setValue(k, v)
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(mat, mat)
        ksp.setFromOptions()
    rhs = frame_vec(bare_frame(A, b, ""), mat)
    x = rhs.duplicate()
    x.set(0.0)
    ksp.solve(rhs, x)
    r = b - A @ x.getArray()
    if np.abs(A.sum(axis=1)).max() <= 1e-10 * np.abs(A.diagonal()).max():
        r = r - r.mean()
    return ksp.getConvergedReason(), ksp.getIterationNumber(), np.linalg.norm(r) / np.linalg.norm(b), ksp, mat


def lines(ksp) -> str:
    return "\n".join(ksp.getPC().getPythonContext().setup.describe())


# ------------------------------------------------------------------ leaves and graph

@pytest.mark.parametrize("second, low, high", [("standard", 10, 40), ("pairs", 6, 16)])
def test_aggregation_leaves_cover_every_row_and_keep_decoupled_rows_apart(second, low, high):
    """Both kinds of second pass cover every row once, keep decoupled rows apart and give leaves of their size:
    standard aggregation 10-40 rows on average, pairs of the first pass's aggregates (3-9 rows each) 6-16."""
    A, _ = foreign.dmda(2, 40)
    lone = decoupled_rows(A)
    assert lone.sum() == 4 * 39                           # the DMDA's boundary layer: identity rows, zeros stored
    part = aggregates(A, second=second)
    assert part.min() == 0 and np.all(np.bincount(part) > 0)
    assert not set(part[lone]) & set(part[~lone])         # decoupled rows share no leaf with coupled ones
    assert np.bincount(part[lone]).max() <= DECOUPLED_LEAF
    sizes = np.bincount(part[~lone])
    sizes = sizes[sizes > 0]
    assert low <= sizes.mean() <= high, sizes.mean()
    leaves = choose_leaves(A, second=second)
    assert leaves.kind == "aggregation" and np.array_equal(np.sort(leaves.perm), np.arange(A.shape[0]))
    with pytest.raises(ValueError, match="unknown aggregation pass 'triples'"):
        aggregates(A, second="triples")


@pytest.mark.parametrize("passes, second", [(1, "standard"), (2, "standard"), (2, "pairs")])
def test_decoupled_rows_leave_the_coupled_rows_aggregates_as_their_submatrix_would(passes, second):
    """The passes run on A itself, where decoupled rows stand alone in the strong graph: the coupled rows' leaves are
    those of the submatrix of the coupled rows alone (numbered the same), in 2-D and 3-D."""
    for A in (foreign.dmda(2, 40)[0], foreign.dmda(3, 16)[0]):
        keep = np.flatnonzero(~decoupled_rows(A))
        part = aggregates(A, passes=passes, second=second)
        alone = aggregates(A[keep][:, keep].tocsr(), passes=passes, second=second)
        assert keep.size < A.shape[0] and np.array_equal(part[keep], alone), (passes, second)


@pytest.mark.parametrize("second", ["standard", "pairs"])
def test_aggregation_keeps_strongly_coupled_rows_together(second):
    """A jump of 1e6 across x = 1/2: no leaf holds rows on both sides."""
    side = 32
    k = np.ones((side, side))
    k[:, side // 2:] = 1e6
    A, _ = foreign.lognormal(side, 1.0)                   # the pattern; values from k below
    y, x = np.divmod(np.arange(side * side), side)
    rows = np.repeat(np.arange(side * side), np.diff(A.indptr))
    w = 2 * k.ravel()[rows] * k.ravel()[A.indices] / (k.ravel()[rows] + k.ravel()[A.indices])
    off = rows != A.indices
    data = np.where(off, -w, 0.0)
    data[~off] = -np.bincount(rows[off], data[off], side * side) + 4 * k.ravel()
    A = sp.csr_matrix((data, A.indices, A.indptr), shape=A.shape)
    part = aggregates(A, second=second)
    left = x < side // 2
    assert not set(part[left]) & set(part[~left])


@pytest.mark.parametrize("case, dim", [(lambda: foreign.dmda(2, 48), 2), (lambda: foreign.anisotropic(48), 2),
                                       (lambda: meshes.p1_laplacian(2, 3000), 2), (lambda: foreign.dmda(3, 20), 3),
                                       (lambda: meshes.p1_laplacian(3, 4000), 3)],
                         ids=["dmda2d", "9-point", "triangles", "dmda3d", "tets"])
def test_graph_shape_tells_the_dimension_whatever_the_nonzeros_per_row(case, dim):
    A, _ = case()
    shape = graph_shape(A)
    assert shape.dim == dim, shape.describe()
    assert f"{dim}-D" in shape.describe()


def test_graph_shape_follows_nonzeros_only_and_finds_rare_coupled_rows():
    """Stored zeros couple nothing: a 3-D 7-point matrix whose couplings across planes are explicit zeros is 2-D.
    Where coupled rows are rare (a 2-D block in a large identity), the seeds are still found among them."""
    A, _ = foreign.dmda(3, 20)
    A = sp.csr_matrix(A, copy=True)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    A.data[np.abs(A.indices - rows) >= 400] = 0.0                  # couplings to the planes above and below
    assert graph_shape(A).dim == 2 and A.nnz == foreign.dmda(3, 20)[0].nnz
    B, _ = foreign.dmda(2, 30)
    shape = graph_shape(sp.block_diag([sp.identity(200000), B]).tocsr())
    assert shape.dim == 2 and not np.isnan(shape.growth), shape.describe()


def test_a_chain_is_told_by_its_balls_and_its_rows():
    """sizing.chain: a 1-D Laplacian's balls grow as r (exponent below LINEAR_GROWTH) and its rows hold 3 entries;
    the rows of a 2-D grid in a random order break a rank's block into pieces whose balls barely grow either, but
    their rows hold 5: not a chain (its coarse LU would fill)."""
    n = 20000
    chain = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (n, n)).tocsr()
    shape = graph_shape(chain)
    assert shape.growth < sizing.LINEAR_GROWTH and sizing.chain(shape.growth, chain.nnz / n)
    grid, _ = foreign.dmda(2, 100)
    assert not sizing.chain(graph_shape(sp.csr_matrix(grid)).growth, grid.nnz / grid.shape[0])
    assert not sizing.chain(0.72, 5.0) and not sizing.chain(np.inf, 3.0)


def test_every_ball_search_gives_the_same_balls():
    """The breadth-first search, the sparse products and the shortest paths grow the same balls, stored zeros
    coupling nothing (the search is picked by cost only)."""
    from petsc_htp.twolevel import graphshape as gs

    A, _ = foreign.dmda(3, 12)
    A = sp.csr_matrix(A, copy=True)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    A.data[(A.indices - rows) % 7 == 3] = 0.0                       # stored zeros here and there
    for M in (A, meshes.p1_laplacian(3, 2000)[0].tocsr(), foreign.dmda(2, 40)[0].tocsr()):
        seeds = gs._coupled_seeds(M, gs.SAMPLES, np.random.default_rng(1)).astype(np.int64)
        bfs, products = gs._ball_sizes(M, seeds, gs.RADIUS), gs._ball_sizes_by_products(M, seeds, gs.RADIUS)
        np.testing.assert_array_equal(bfs, products)
        np.testing.assert_array_equal(bfs, gs._ball_sizes_by_paths(M, seeds, gs.RADIUS))
        assert (bfs[1] > bfs[0]).all()
    assert gs._by_products(meshes.p1_laplacian(3, 8000)[0].tocsr()) and not gs._by_products(foreign.dmda(2, 256)[0])
    tets = meshes.p1_laplacian(3, 8000)[0].tocsr()
    dense = sp.kron(tets, np.ones((5, 5)), format="csr")           # 5 unknowns a node: 75 entries a row, 3M in all
    assert dense.nnz > gs.PRODUCTS[2] and gs._by_products(dense)
    assert not gs._by_products(sp.kron(foreign.dmda(3, 64)[0], np.ones((3, 3)), format="csr"))    # 21 a row, 5M


def test_a_dense_row_is_reached_but_not_grown_through():
    """An arrow matrix (a chain and one row coupled to all): the balls follow the chain, so a ball of radius 4 holds
    at most its 9 chain rows and the dense row, in every search, and HTPPC solves it."""
    from petsc_htp.twolevel import graphshape as gs

    n = 20000
    chain = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], (n, n), format="lil")
    chain[0, 1:] = 0.01
    chain[1:, 0] = 0.01
    A = chain.tocsr()
    seeds = gs._coupled_seeds(A, gs.SAMPLES, np.random.default_rng(0)).astype(np.int64)
    G = gs._without_hubs(A)
    assert G is not A and gs._without_hubs(B := foreign.dmda(2, 40)[0]) is B
    for search in (gs._ball_sizes, gs._ball_sizes_by_products, gs._ball_sizes_by_paths):
        assert search(G, seeds, gs.RADIUS).max() <= 2 * 2 * gs.RADIUS + 2
    assert graph_shape(A).dim == 2
    reason, its, relres, _, _ = solve(A, np.ones(n))
    assert reason > 0 and its <= 20 and relres <= 1e-8, (reason, its, relres)


def test_graph_shape_counts_weak_and_positive_couplings():
    """The weak share follows the anisotropy; the positive share tells a rotated anisotropy's 9-point stencil (a
    quarter of its couplings) from a mesh Laplacian's rows (none), which pair their aggregates (sizing.aggregation)."""
    strong, _ = foreign.anisotropic(40, 1.0, 0.0)
    weak, _ = foreign.anisotropic(40, 1e-4, 0.0)
    assert graph_shape(strong).weak < 0.05 < 0.3 < graph_shape(weak).weak
    rotated = graph_shape(sp.csr_matrix(CASES["aniso_e0.01_a30"](4096, 0)[0]))
    mesh = graph_shape(sp.csr_matrix(CASES["fem_tri"](4096, 0)[0]))
    assert mesh.positive <= sizing.POSITIVE_MAX < 0.2 <= rotated.positive
    assert "0% positive" in mesh.describe()
    assert sizing.aggregation(2, 0, 7.0, "auto", mesh.positive) == "pairs"
    assert sizing.aggregation(2, 0, 9.0, "auto", rotated.positive) == "standard"
    assert sizing.aggregation(2, 0, 9.0, "auto", rotated.positive, split=0.5) == "pairs"     # blocks fall apart
    assert sizing.aggregation(2, 0, 9.0, "auto", rotated.positive, split=0.2) == "standard"
    assert sizing.aggregation(2, 0, 9.0, "eig", rotated.positive, split=0.5) == "standard"   # the user's space


def _lap27(m):
    """A 27-point Laplacian on an m^3 grid (off-diagonals -1, diagonal 26): every coupling 1/26 of the diagonal."""
    one = sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], (m, m))
    return (27.0 * sp.identity(m ** 3) - sp.kron(sp.kron(one, one), one)).tocsr()


def test_wide_rows_lower_the_strength_threshold():
    """Where the median row holds no coupling as strong as THETA (a 27-point stencil's are 1/26 of the diagonal), the
    threshold drops to half that row's largest share, so aggregates form (at THETA each row stood alone and the coarse
    operator was A itself); 5- and 7-point stencils, 9-point anisotropy and P1 tets keep THETA. HTPPC reaches its
    rtol in 20 iterations, and -ksp_view says what it took."""
    for A in (foreign.dmda(2, 40)[0], foreign.dmda(3, 16)[0], foreign.anisotropic(40)[0],
              meshes.p1_laplacian(3, 3000)[0]):
        assert threshold(sampled_shares(sp.csr_matrix(A))[1]) == THETA
    rotated = sp.csr_matrix(CASES["aniso_e0.001_a45"](12000, 0)[0])      # the second pass keeps the first's theta:
    assert np.bincount(aggregates(rotated, second="standard")).mean() < 16   # its graph's own gave 51-row leaves
    A = _lap27(22)                                  # the two-level method (as it comes: ICC(0), wide rows)
    assert threshold(sampled_shares(A)[1]) == pytest.approx(0.5 / 26)
    assert np.bincount(aggregates(A, second="pairs")).min() >= 8
    reason, its, relres, ksp, _ = solve(A, np.random.default_rng(0).standard_normal(A.shape[0]), htp_direct_max="0")
    assert reason > 0 and its <= 20 and relres <= 1e-8, (reason, its, relres)
    assert "strong couplings from 0.0192 (wide rows)" in lines(ksp)


# ------------------------------------------------------------------ HTPPC on foreign matrices

@pytest.mark.parametrize("case, second, coarse", [
    ("dmda2d", "pairs", "const"), ("dmda3d", "pairs", "const"), ("free_surface", "pairs", "const"),
    ("fem_tri", "pairs", "const"), ("fem_tet", "pairs", "const"),
    ("fem_hex", "pairs", "const"), ("lognormal", "pairs", "const"), ("neumann", "pairs", "const")])
def test_default_converges_within_40_iterations_on_foreign_matrices(case, second, coarse):
    """The defaults by what the graph shows: in 3-D, and in 2-D where rows are as sparse as a 5-point stencil's or
    no coupling is positive (P1 triangles), the first pass's aggregates paired, with the const space (rotated
    anisotropy: test_strongly_rotated_anisotropy_gets_icc_of_the_whole_matrix_on_one_rank; Q1 hexahedra, which as
    they come take ICC(0): test_wide_rows_get_icc_of_the_whole_matrix, here two-level; sparse 2-D rows at this size
    take a banded factor: test_the_whole_matrix_factor_is_sized_by_the_problem)."""
    A, b = CASES[case](12000, 0)              # the two-level method (its banded factor would take most of these)
    reason, its, relres, ksp, _ = solve(A, b, htp_direct_max="0")
    assert reason > 0 and its <= 40 and relres <= 1e-8, (case, reason, its, relres)
    text = lines(ksp)
    assert "leaves: aggregation" in text and "graph:" in text
    assert f"second pass {second} (leaf, coarse and aggregation by the problem" in text, text
    assert f"coarse: {coarse} (" in text, text


def test_decoupled_rows_get_no_coarse_vector():
    A, b = foreign.dmda(3, 20)
    reason, its, relres, ksp, _ = solve(A, b, htp_direct_max="0")       # the two-level method at this size
    setup = ksp.getPC().getPythonContext().setup
    lone = int(decoupled_rows(A).sum())
    assert reason > 0 and its <= 40 and relres <= 1e-8
    assert setup.st.m == int(setup.st.ncols.sum()) and setup.st.m < A.shape[0] - lone
    assert f"{lone} of them decoupled rows (no coarse vector)" in lines(ksp)
    assert np.count_nonzero(setup.st.ncols) == setup.st.ncols.size - int(np.ceil(lone / DECOUPLED_LEAF))


@pytest.mark.parametrize("name", list(pyamg_cases()))
@pytest.mark.parametrize("ksp_type", ["cg", "gmres", "minres"])
def test_small_matrices_get_one_factor_and_any_ksp_converges(name, ksp_type):
    """Sparse rows: one Cholesky factor (one iteration); richer rows (9-point, P1, elasticity-like): ICC(0)."""
    A, b = pyamg_cases()[name]
    reason, its, relres, ksp, _ = solve(A, b, ksp_type)
    assert reason > 0 and relres <= 1e-8, (reason, its, relres)
    text = lines(ksp)
    exact = A.nnz / A.shape[0] <= sizing.RICH_ROW
    assert text.startswith("whole matrix: " + ("one sparse Cholesky factor" if exact else "ICC(0)")), text
    assert its <= 2 or not exact


def test_small_singular_matrix_is_grounded():
    A, b = foreign.neumann(40)
    reason, its, relres, ksp, _ = solve(A, b)
    assert reason > 0 and its <= 2 and relres <= 1e-8
    assert "1 null component(s) grounded" in lines(ksp)


def test_a_null_space_that_appears_on_new_values_of_a_preallocated_again_matrix_is_grounded():
    """The small-matrix factor finds the graph's components only once a null space may be there, from the rows of
    that setup: a 1-D Laplacian shifted first (no null space), then preallocated again and refilled with Neumann
    values on the same KSP (a program that preallocates every frame), is grounded and converges."""
    n = 3000
    lap = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tolil()
    lap[0, 0] = lap[n - 1, n - 1] = 1.0                          # Neumann ends: row sums vanish
    neumann = lap.tocsr()
    shifted = (neumann + sp.identity(n)).tocsr()
    b = np.random.default_rng(0).standard_normal(n)
    b -= b.mean()
    reason, _, relres, ksp, mat = solve(shifted, b)
    assert reason > 0 and relres <= 1e-8 and "null component" not in lines(ksp)
    mat.setPreallocationNNZ(3)
    for i in range(n):
        cols = neumann.indices[neumann.indptr[i]:neumann.indptr[i + 1]]
        mat.setValues(i, cols, neumann.data[neumann.indptr[i]:neumann.indptr[i + 1]])
    mat.assemble()
    reason, _, relres, ksp, _ = solve(neumann, b, mat=mat, ksp=ksp)
    assert reason > 0 and relres <= 1e-8 and "1 null component(s) grounded" in lines(ksp)


def test_direct_max_zero_keeps_the_two_level_method():
    A, b = foreign.neumann(20)
    reason, its, relres, ksp, _ = solve(A, b, htp_direct_max="0")
    assert reason > 0 and 2 < its <= 40 and "leaves: aggregation" in lines(ksp)


@pytest.mark.parametrize("case, n, kind", [("dmda2d", 7900, "banded Cholesky"), ("dmda2d", 8200, "banded Cholesky"),
                                           ("free_surface", 16000, "banded Cholesky"), ("dmda2d", 16900, None),
                                           ("dmda3d", 1000, "ICC(0)"), ("dmda3d", 8000, "ICC(0)"),
                                           ("dmda3d", 9261, None), ("fem_tri", 4000, "ICC(0)")])
def test_the_whole_matrix_factor_is_sized_by_the_problem(case, n, kind):
    """sizing.whole_factor: ICC(0) for richer rows or a 3-D graph up to WHOLE_ICC_MAX; a banded Cholesky factor
    (one rank) where the reverse Cuthill-McKee order's bandwidth is at most BAND_WIDTH (sparse 2-D rows up to about
    12 500 rows, a free surface's further); the two-level method above."""
    A, b = CASES[case](n, 0)
    reason, its, relres, ksp, _ = solve(A, b)
    assert reason > 0 and relres <= 1e-8
    text = lines(ksp)
    assert (text.startswith("whole matrix:") and kind in text) if kind else "leaves: aggregation" in text, text


def _random_graph(n, per_row, seed=0) -> sp.csr_matrix:
    """The Laplacian + 0.01 I of a random graph of ``n`` nodes, each joined to ``per_row`` random others."""
    rng = np.random.default_rng(seed)
    rows, cols = np.repeat(np.arange(n), per_row), rng.integers(0, n, per_row * n)
    keep = rows != cols
    W = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(n, n))
    W = ((W + W.T) > 0).astype(float)
    A = sp.csr_matrix(sp.diags(np.asarray(W.sum(axis=1)).ravel() + 0.01) - W)
    A.sort_indices()
    return A


def _on_two_ranks(A, path, b=None):
    """``A`` (and the right-hand side ``b``, else ones) written to the PETSc binary file ``path`` and solved by
    examples/matrix_file.py on 2 ranks with HTPPC as it comes (-ksp_view): the finished process."""
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data),
                                comm=PETSc.COMM_SELF)
    viewer = PETSc.Viewer().createBinary(str(path), "w", comm=PETSc.COMM_SELF)
    mat.view(viewer)
    if b is not None:
        PETSc.Vec().createWithArray(b, comm=PETSc.COMM_SELF).view(viewer)
    viewer.destroy()
    return _mpirun(2, EXAMPLE.parent / "matrix_file.py", "-f", str(path), *HTPPC_FLAGS)


def test_rows_strongly_coupled_to_another_rank_are_leaves_of_their_own(tmp_path):
    """A random field of contrast 1e4 (a fifth of the couplings strong): a strong coupling that joins two ranks
    cannot lie inside a leaf, and the pair's common mode left the coarse space (CG: 21 iterations on one rank, 85 on
    two, now 29); rows whose couplings to the other rank weigh half their diagonal, and more than half of all their
    couplings, are leaves of one row each, so the mode lies in their coarse columns. A split that cuts many such rows
    (more than ranksplit.CUT_ROWS) makes none, nor does a Q1 stencil whose couplings weigh twice its diagonal
    (PETSc's ksp ex3: the rows beside the cut had been leaves of one row)."""
    from petsc_htp.ranksplit import CUT_ROWS, CUT_SHARE, cut_rows

    side, rng = 128, np.random.default_rng(2)
    kx = np.where(rng.random((side + 1, side)) < 0.2, 1e4, 1.0)        # kx[i, j]: between nodes (i - 1, j), (i, j)
    ky = np.where(rng.random((side, side + 1)) < 0.2, 1e4, 1.0)        # Dirichlet nodes around, eliminated
    node = np.arange(side * side).reshape(side, side).T                  # node (i, j) is row j * side + i
    x_edges = sp.coo_matrix((-kx[1:-1].ravel(), (node[:-1].ravel(), node[1:].ravel())), shape=(side * side,) * 2)
    y_edges = sp.coo_matrix((-ky[:, 1:-1].ravel(), (node[:, :-1].ravel(), node[:, 1:].ravel())),
                            shape=(side * side,) * 2)
    diag = (kx[:-1] + kx[1:] + ky[:, :-1] + ky[:, 1:]).T.ravel()       # in row order
    A = (x_edges + x_edges.T + y_edges + y_edges.T + sp.diags(diag)).tocsr()
    half = side * side // 2
    cut = cut_rows(A[:half], A[:half, :half].tocsr())
    assert 0 < np.count_nonzero(cut) <= CUT_ROWS * half
    total, inside = (np.asarray(abs(M).sum(axis=1)).ravel() for M in (A[:half], A[:half, :half]))
    d = np.abs(A.diagonal()[:half])                                    # the rows' sums over every row, as defined
    assert np.array_equal(cut, (total - inside >= CUT_SHARE * d) & (total - inside > CUT_SHARE * (total - d)))
    assert not cut_rows(A[:half], sp.csr_matrix(A[:half, :half].diagonal() * sp.identity(half))).any()   # all cut
    J, I = sp.diags([1.0, 1.0], [-1, 1], (side, side)), sp.identity(side)
    Q1 = (8 * sp.kron(I, I) - 3 * (sp.kron(I, J) + sp.kron(J, I)) + sp.kron(J, J)).tocsr()   # ex3's signs: corners +1
    assert not cut_rows(Q1[:half], Q1[:half, :half].tocsr()).any()
    b = np.random.default_rng(3).standard_normal(side * side)
    reason, its, relres, _, _ = solve(A, b)
    proc = _on_two_ranks(A, tmp_path / "field.petsc", b)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    two = int(proc.stdout.split("iterations:")[1].split()[0])
    assert reason > 0 and relres <= 1e-8 and two <= 1.5 * its + 2, (its, two)


def test_a_graph_that_is_no_mesh_gets_icc_of_the_whole_matrix_at_any_size(tmp_path):
    """A random graph of degree about 6 (its balls grow exponentially, no mesh's do) above the small-matrix sizes:
    one rank takes ICC(0) of the whole matrix and -ksp_view says why; -htp_direct_max 0 keeps the two-level method.
    On two ranks (examples/matrix_file.py) ICC(0) of each rank's block, PCBJACOBI: for the graph of degree about 12,
    whose ranks' blocks keep about 6 couplings a row, by the blocks' growth; for the same graph of degree about 6,
    whose blocks keep about 3 and grow no faster than a mesh, by the whole graph's (:mod:`.twolevel.spread`). P1
    triangles numbered at random cut as many couplings between the ranks and stay two-level. A 2-D grid of the same
    size stays two-level (test_the_whole_matrix_factor_is_sized_by_the_problem)."""
    from petsc_htp.twolevel import spread
    from petsc_htp.twolevel.graphshape import graph_shape
    from petsc_htp.twolevel.sizing import EXPANDER_GROWTH

    A = _random_graph(12000, 3)
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    reason, its, relres, ksp, _ = solve(A, b)
    text = lines(ksp)
    assert reason > 0 and relres <= 1e-8 and text.startswith("whole matrix: ICC(0)") and "graph is no mesh" in text
    reason, its2, relres, ksp, _ = solve(A, b, htp_direct_max="0")
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp)
    assert graph_shape(A[:6000, :6000].tocsr(), want_weak=False, samples=8).growth < EXPANDER_GROWTH
    script = EXAMPLE.parent / "matrix_file.py"
    for per_row in (6, 3):
        proc = _on_two_ranks(_random_graph(12000, per_row), tmp_path / f"graph{per_row}.petsc")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        assert "ICC(0) of each rank's diagonal block (PCBJACOBI)" in proc.stdout and relres <= 1.01e-8, proc.stdout
    proc = _mpirun(2, script, "-case", "fem_tri", "-n", "12000", *HTPPC_FLAGS)
    assert proc.returncode == 0 and "leaves: aggregation" in proc.stdout, proc.stdout + proc.stderr
    share = float(proc.stdout.split("ranks: 2; ")[1].split("%")[0]) / 100   # the whole graph's growth was measured
    assert share >= spread.CROSSING and "no mesh" not in proc.stdout, proc.stdout


def test_strongly_rotated_anisotropy_gets_icc_of_the_whole_matrix(tmp_path):
    """Rotated anisotropy (eps 0.01 and 0.001, 9-point, above the small-matrix sizes; FE at 30 degrees): the positive
    couplings weigh 0.15 of the diagonal or more and ICC(0)'s trial confirms, so one rank takes ICC(0) of the whole
    matrix, -ksp_view says why, and it takes fewer iterations than the two-level method (-htp_direct_max 0:
    standard passes, eig space); penalty rows keep it. Numbered at random, the same matrix fails the trial (ICC(0)
    follows no line there) and stays two-level. On two ranks ICC(0) of each rank's block grown by 4 layers
    (PCASM)."""
    from petsc_htp.twolevel import incomplete

    for case in ("aniso_e0.01_a30", "aniso_e0.001_a45"):
        A, b = CASES[case](12000, 0)
        assert incomplete.positive_weight(sp.csr_matrix(A)) >= incomplete.WEIGHT
        reason, its, relres, ksp, _ = solve(A, b)
        text = lines(ksp)
        assert reason > 0 and relres <= 1e-8 and its <= 30, (case, its, relres)
        assert text.startswith("whole matrix: ICC(0)") and "strongly anisotropic rows" in text, text
        assert float(text.split("setup ms: analysis ")[1].split(";")[0]) > 0, text     # the trial is counted
        reason, its2, relres, ksp, _ = solve(A, b, htp_direct_max="0")
        text = lines(ksp)
        assert reason > 0 and relres <= 1e-8 and its2 > its, (its, its2)
        assert "second pass standard" in text and "coarse: eig (" in text, text
    A, b = CASES["aniso_e0.001_a45"](65536, 0)                     # penalty rows (1e30) keep ICC(0): 0.13
    held = (sp.csr_matrix(A) + sp.diags(A.diagonal().max() * 1e30 * (np.arange(A.shape[0]) % 300 == 0))).tocsr()
    reason, _, relres, ksp, _ = solve(held, b)                      # on the trial, 0.03 without them
    assert reason > 0 and relres <= 1e-8 and lines(ksp).startswith("whole matrix: ICC(0)"), lines(ksp)
    from pyamg.gallery import diffusion_stencil_2d, stencil_grid

    fe30 = stencil_grid(diffusion_stencil_2d(0.001, np.pi / 6, "FE"), (110, 110), format="csr")   # weight 0.198
    reason, its, relres, ksp, _ = solve(fe30, np.random.default_rng(1).standard_normal(fe30.shape[0]))
    assert reason > 0 and relres <= 1e-8 and its <= 30 and lines(ksp).startswith("whole matrix: ICC(0)"), its
    A, b = CASES["aniso_e0.001_a45"](12000, 0)
    p = np.random.default_rng(0).permutation(A.shape[0])
    shuffled = sp.csr_matrix(A)[p][:, p].tocsr()
    assert incomplete.trial_drop(frame_mat(bare_frame(shuffled, b[p], ""), PETSc.COMM_SELF),
                                 incomplete.window(shuffled)) > incomplete.TRIAL_DROP
    reason, _, relres, ksp, _ = solve(shuffled, b[p])
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp)
    proc = _on_two_ranks(sp.csr_matrix(A), tmp_path / "rotated.petsc")
    assert proc.returncode == 0 and "strongly anisotropic rows" in proc.stdout, proc.stdout + proc.stderr
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert "ICC(0) of each rank's block grown by 4 layers (PCASM, basic)" in proc.stdout and relres <= 1.01e-8


def test_icc_for_anisotropy_is_not_taken_by_singular_or_isotropic_matrices_and_left_when_values_lose_it():
    """No trial where the positive couplings weigh little (P1 triangles) or the matrix is singular (rotated
    anisotropy with no-flux walls and the constant attached: the trial's ball is not singular, but ICC(0) of the
    whole matrix stalled); new values of the ICC(0) pattern that lose the weight (the same stencil, eps 1) make a new
    analysis; at this size both take the banded factor (bandwidth 110)."""
    from petsc_htp.twolevel import incomplete

    T, t = CASES["fem_tri"](12000, 0)
    assert incomplete.positive_weight(sp.csr_matrix(T)) < incomplete.WEIGHT
    A, b = CASES["aniso_e0.001_a45"](12000, 0)
    A = sp.csr_matrix(A)
    N = (A - sp.diags(np.asarray(A.sum(axis=1)).ravel())).tocsr()         # row sums 0: the no-flux matrix
    N.sort_indices()
    r = np.random.default_rng(0).standard_normal(N.shape[0])
    reason, its, relres, ksp, _ = solve(N, r - r.mean())
    assert reason > 0 and relres <= 1e-8 and "banded Cholesky" in lines(ksp), (reason, its, relres)
    reason, its, relres, ksp, mat = solve(A, b)
    ctx = ksp.getPC().getPythonContext()
    assert lines(ksp).startswith("whole matrix: ICC(0)") and ctx.analysis_count == 1
    side = int(round(A.shape[0] ** 0.5))
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    eps1 = sp.csr_matrix(foreign.anisotropic(side, 1.0, np.pi / 4)[0])
    iso = sp.csr_matrix((np.asarray(eps1[rows, A.indices]).ravel(), A.indices, A.indptr), shape=A.shape)   # A's pattern
    mat.setValuesCSR(iso.indptr, iso.indices, iso.data)
    mat.assemble()
    reason, its, relres, _, _ = solve(iso, b, mat=mat, ksp=ksp)
    assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == 2 and "banded Cholesky" in lines(ksp)


def test_a_heat_step_with_shifted_rows_gets_icc_of_the_whole_matrix(tmp_path):
    """One backward-Euler step of the heat equation on P1 tetrahedra, M + dt K at dt = 10 h^2 (mass couplings of
    both signs, so no diagonal dominance): its rows sum to SHIFT of the diagonal or more and ICC(0)'s trial on a
    small ball confirms, so one rank takes ICC(0) of the whole matrix and -ksp_view says why; new values that lose
    the shift (the stiffness alone, on the same pattern) make a new analysis, the two-level method's; a long step
    (1000 h^2) and the Laplacian stay two-level. On two ranks ICC(0) of each rank's block (PCBJACOBI)."""
    from petsc_htp.twolevel import dominance, incomplete

    A, b = meshes.p1_heat(3, 12000, 10.0)
    assert incomplete.row_sum_share(A) >= incomplete.SHIFT and dominance.margin(A, 0) < dominance.MARGIN
    reason, its, relres, ksp, mat = solve(A, b)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and relres <= 1e-8 and its <= 40, (its, relres)
    assert lines(ksp).startswith("whole matrix: ICC(0)") and "shifted rows" in lines(ksp), lines(ksp)
    for values, count, text in ((meshes.p1_heat(3, 12000, 10.0, frame=1)[0], 1, "whole matrix: ICC(0)"),
                                (meshes.p1_laplacian(3, 12000)[0], 2, "leaves: aggregation")):
        assert np.array_equal(values.indptr, A.indptr) and np.array_equal(values.indices, A.indices)
        mat.setValuesCSR(values.indptr, values.indices, values.data)     # a new step size keeps the analysis, the
        mat.assemble()                                                   # stiffness alone loses the shift
        reason, _, relres, _, _ = solve(values, b, mat=mat, ksp=ksp)
        assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == count and text in lines(ksp), lines(ksp)
    long_step, _ = meshes.p1_heat(3, 12000, 1000.0)
    assert incomplete.row_sum_share(long_step) < incomplete.SHIFT
    reason, _, relres, ksp, _ = solve(long_step, b)
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp)
    aniso, r = CASES["aniso_e0.001_a45"](12000, 0)                  # anisotropic and shifted: the anisotropy's rule
    shifted = (sp.csr_matrix(aniso) + 0.01 * sp.diags(aniso.diagonal())).tocsr()
    assert incomplete.row_sum_share(shifted) >= incomplete.SHIFT
    reason, _, relres, ksp, _ = solve(shifted, r)
    assert reason > 0 and relres <= 1e-8 and "strongly anisotropic rows" in lines(ksp), lines(ksp)
    proc = _on_two_ranks(A, tmp_path / "heat.petsc")
    assert proc.returncode == 0 and "shifted rows" in proc.stdout, proc.stdout + proc.stderr
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert "ICC(0) of each rank's diagonal block (PCBJACOBI)" in proc.stdout and relres <= 1.01e-8


def test_a_preonly_ksp_gets_exact_factors_or_the_two_level_method_not_icc():
    """A KSPPREONLY applies M once (PCMG's coarse solve, PCFIELDSPLIT's splits), and one ICC(0) is no solve: where
    ICC(0) was chosen for its iterations the first such solve makes a new analysis, an exact factor at the small
    sizes and the two-level method above (PCMG's 9-point coarse level of 4 225 rows had taken the outer CG to 31
    iterations, 8 with its Cholesky). A CG KSP on the same matrices keeps ICC(0)."""
    side = 65
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    nine = (sp.kron(T, T) + sp.kronsum(T, T)).tocsr()                  # rich rows: ICC(0) at this size
    big = (sp.kronsum(*2 * [sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (120, 120))]) + 0.5 * sp.identity(14400)).tocsr()
    for A, once in ((nine, "one sparse Cholesky factor"), (big, "leaves: aggregation")):
        b = np.random.default_rng(1).standard_normal(A.shape[0])
        assert lines(solve(A, b)[3]).startswith("whole matrix: ICC(0)")
        reason, its, relres, ksp, _ = solve(A, b, ksp_type="preonly", ksp_norm_type="none")
        ctx = ksp.getPC().getPythonContext()
        assert reason > 0 and ctx.analysis_count == 2 and once in lines(ksp), lines(ksp)
        assert relres <= (1e-10 if A is nine else 0.5), relres          # exact, or one two-level application
        if A is nine:
            assert "applied once (KSPPREONLY)" in lines(ksp)
        ksp.solve(*ksp.getOperators()[0].createVecs())                  # later solves keep it (no third analysis)
        assert ctx.analysis_count == 2
        for name in ("ksp_rtol", "ksp_max_it", "ksp_norm_type"):          # options a PREONLY KSP does not read
            PETSc.Options(ksp.getOptionsPrefix()).delValue(name)


@pytest.mark.parametrize("ksp_type", ["richardson", "chebyshev", "cgs"])
def test_dominant_rows_keep_icc_under_the_iterations_that_take_no_icc_elsewhere(ksp_type):
    """Richardson, Chebyshev and CGS take exact factors or the two-level method where ICC(0) was chosen for its
    iterations (:data:`petsc_htp.variants.FIXED`), but above the whole factors' sizes diagonally dominant rows keep
    ICC(0), whose M A stays near 1 there (the V-cycles took Chebyshev 2.6 x its time on the 512^2 5-point matrix + 2 I,
    32 steps either way: results/kspsweep-20261129/dominant.txt)."""
    big = (sp.kronsum(*2 * [sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (120, 120))]) + 0.5 * sp.identity(14400)).tocsr()
    b = np.random.default_rng(1).standard_normal(big.shape[0])
    reason, its, relres, ksp, _ = solve(big, b, ksp_type=ksp_type)
    assert reason > 0 and relres <= 1.1e-8 and its <= 60, (reason, its, relres)
    assert lines(ksp).startswith("whole matrix: ICC(0)"), lines(ksp)


def test_the_deflated_start_solves_the_coarse_part_and_adds_no_null_component():
    """The deflated form's start x0 = W E^-1 W^T b: under V-cycles it is refined until W^T r0 is below a tenth of the
    KSP's tolerance (PETSc's ex2, A u = b for u = 1 on a 5-point Laplacian, took 97 CG iterations at 250 000 rows on
    one rank and 115 on two after one start of two V-cycles, where a random b takes 27); on a Neumann matrix with its
    null space attached the start adds no constant (CG from zero returns the mean-free solution, as with any PC:
    PETSc's ex34 had printed an error of 0.27, its solution's offset)."""
    side = 300
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
    A = sp.kronsum(T, T).tocsr()
    reason, its, relres, ksp, _ = solve(A, A @ np.ones(side * side), htp_coarse_solver="gamg")
    assert reason > 0 and relres <= 1e-8 and its <= 5 and "V-cycles" in lines(ksp), (its, lines(ksp))
    K, b = CASES["neumann"](16384, 0)[:2]
    b = b - b.mean()
    _, _, _, ksp, mat = solve(K, b)
    assert mat.getNullSpace().handle
    x = mat.createVecRight()
    ksp.solve(frame_vec(bare_frame(K, b, ""), mat), x)
    assert abs(x.getArray().mean()) <= 1e-10 * np.sqrt(np.mean(x.getArray() ** 2))
    x.setArray(5.0 + np.random.default_rng(4).random(K.shape[0]))     # a guess keeps its own null component
    ksp.setInitialGuessNonzero(True)
    ksp.solve(frame_vec(bare_frame(K, b, ""), mat), x)
    assert ksp.getConvergedReason() > 0 and abs(x.getArray().mean() - 5.5) < 0.01, x.getArray().mean()


def test_a_growing_time_step_makes_the_shifted_rows_trial_again():
    """A time step that grows on one KSP (a TS with adaptive steps): values whose row sums fell below half the share
    ICC(0) was chosen at make a new analysis, whose trial chooses again (a 2-D heat step of 65 536 rows had kept
    ICC(0) from 44 to 143 CG iterations a step, where a fresh KSP took the two-level method's 25); a step that loses
    less keeps the analysis, and each takes the iterations of a fresh KSP."""
    from petsc_htp.twolevel import incomplete

    A, b = meshes.p1_heat(3, 12000, 1.0)
    reason, its, relres, ksp, mat = solve(A, b)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and "shifted rows (row sums 0.12" in lines(ksp), lines(ksp)
    for dt, count, text in ((1.5, 1, "shifted rows (row sums 0.12"), (3.0, 2, "shifted rows (row sums 0.044"),
                            (100.0, 3, "leaves: aggregation")):
        values = meshes.p1_heat(3, 12000, dt)[0]
        assert np.array_equal(values.indices, A.indices) and incomplete.row_sum_share(values) >= 0.001
        mat.setValuesCSR(values.indptr, values.indices, values.data)
        mat.assemble()
        reason, its, relres, _, _ = solve(values, b, mat=mat, ksp=ksp)
        fresh = solve(values, b)[1]
        assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == count and text in lines(ksp), lines(ksp)
        assert its <= fresh + 1, (dt, its, fresh)


def test_wide_rows_get_icc_of_the_whole_matrix(tmp_path, monkeypatch):
    """Q1 hexahedra's 27-point rows, whose couplings are weak and none positive: ICC(0)'s trial passes, so one rank
    takes ICC(0) of the whole matrix, the trial's own factor, and -ksp_view says why; new values with a log-normal
    conductivity keep it, values whose couplings turn positive (twice the signless Laplacian of A's couplings added:
    still SPD, the same nonzeros) or whose diagonal jumps by 1e4 make a new analysis; elasticity's rows (positive
    couplings) and conductivity balls of contrast 1e4 take no trial and stay two-level. On two ranks ICC(0) of each
    rank's block (PCBJACOBI)."""
    from petsc_htp.twolevel import incomplete

    trial_drop, taken = incomplete.trial_drop, []

    def recorded(mat, rows, shift=True, kept=None):
        drop = trial_drop(mat, rows, shift, kept)
        taken.extend(pc.handle for pc in kept or [])
        return drop

    monkeypatch.setattr(incomplete, "trial_drop", recorded)
    A, b = CASES["fem_hex"](12000, 0)
    assert A.nnz / A.shape[0] >= incomplete.WIDE_ROW and incomplete.positive_weight(A) < incomplete.WEIGHT
    reason, its, relres, ksp, mat = solve(A, b)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and relres <= 1e-8 and its <= 40, (its, relres)
    assert taken and ctx.setup.pc.handle == taken[-1]                 # the trial's factor is the one applied
    assert lines(ksp).startswith("whole matrix: ICC(0)") and "wide rows (25 stored entries a row" in lines(ksp), \
        lines(ksp)
    reason, its1, relres, ksp1, _ = solve(A, b, htp_leaf_pc_factor_levels="1")   # the user's options win over the
    assert reason > 0 and relres <= 1e-8 and its1 < its                         # trial's factor (ICC(0), applied as
    held = [k.getPC().getPythonContext().setup.pc.getFactorMatrix().getInfo()["nz_used"] for k in (ksp, ksp1)]
    assert held[0] == (A.nnz + A.shape[0]) // 2 < held[1], held                # it is where none is set)
    row = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    off = np.where(A.indices == row, 0.0, np.abs(A.data))            # twice the signless Laplacian of A's couplings
    turned = A.copy()                                                # added: SPD, A's nonzeros
    turned.data = A.data + 2 * off + np.where(A.indices == row, 2 * np.bincount(row, off)[row], 0.0)
    jumped = meshes.q1_laplacian(12000, 0, 1e4)[0]
    for values in (turned, jumped):
        values.sort_indices()
        assert np.array_equal(values.indptr, A.indptr) and np.array_equal(values.indices, A.indices)
        assert np.array_equal(values.data != 0, A.data != 0) and not incomplete.wide(values, 0)
    for values, count in ((CASES["fem_hex"](12000, 1)[0], 1), (turned, 2), (jumped, 3)):
        mat.setValuesCSR(values.indptr, values.indices, values.data)
        mat.assemble()
        reason, _, relres, _, _ = solve(values, b, mat=mat, ksp=ksp)
        assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == count, (count, ctx.analysis_count)
        assert ("wide rows (25 stored entries a row" in lines(ksp)) == (count == 1), lines(ksp)
    elastic = sp.csr_matrix(meshes.q1_elasticity(16)[0])           # above the small sizes
    assert incomplete.positive_weight(elastic) >= incomplete.WEIGHT
    balls = meshes.q1_laplacian(12000, 0, 1e4)[0]                   # jumps: their low modes left to CG
    for M in (elastic, balls):
        reason, _, relres, ksp, _ = solve(M, np.ones(M.shape[0]))
        assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp), lines(ksp)
    proc = _on_two_ranks(A, tmp_path / "hex.petsc")
    assert proc.returncode == 0 and "wide rows" in proc.stdout, proc.stdout + proc.stderr
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert "ICC(0) of each rank's diagonal block (PCBJACOBI)" in proc.stdout and relres <= 1.01e-8


def test_grid_aligned_anisotropy_gets_icc_of_the_whole_matrix(tmp_path):
    """A 5-point stencil whose strong direction follows the grid (eps 0.001): half its couplings are weak and ICC(0)'s
    trial passes, so one rank takes ICC(0) of the whole matrix and -ksp_view says why; isotropic values on the same
    pattern make a new analysis (a banded factor at this size). On two ranks ICC(0) of each rank's block (PCBJACOBI)."""
    from pyamg.gallery import diffusion_stencil_2d, stencil_grid

    from petsc_htp.twolevel import incomplete

    A, iso = (stencil_grid(diffusion_stencil_2d(eps, 0.0, "FD"), (110, 110), format="csr") for eps in (0.001, 1.0))
    assert incomplete.weak_share(A) >= incomplete.WEAK_SHARE > incomplete.weak_share(iso)
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    reason, its, relres, ksp, mat = solve(A, b)
    assert reason > 0 and relres <= 1e-8 and its <= 40, (its, relres)
    assert lines(ksp).startswith("whole matrix: ICC(0)") and "grid-aligned anisotropy" in lines(ksp), lines(ksp)
    assert np.array_equal(iso.indptr, A.indptr) and np.array_equal(iso.indices, A.indices)
    mat.setValuesCSR(iso.indptr, iso.indices, iso.data)
    mat.assemble()
    reason, _, relres, _, _ = solve(iso, b, mat=mat, ksp=ksp)
    assert reason > 0 and relres <= 1e-8 and ksp.getPC().getPythonContext().analysis_count == 2
    assert "banded Cholesky" in lines(ksp), lines(ksp)
    proc = _on_two_ranks(sp.csr_matrix(A), tmp_path / "aligned.petsc")
    assert proc.returncode == 0 and "grid-aligned anisotropy" in proc.stdout, proc.stdout + proc.stderr
    assert "ICC(0) of each rank's diagonal block (PCBJACOBI)" in proc.stdout, proc.stdout


def test_a_chain_gets_a_band_cholesky_factor(tmp_path):
    """A 1-D Laplacian (a chain) above the small sizes, in its own order and numbered at random: one Cholesky factor in
    reverse Cuthill-McKee order, a band of A's size (LAPACK's, bandwidth 1 or 2; the two-level method took 47 ms and
    5 iterations at 64 000 rows), and -ksp_view says why; on two ranks gathered on each (by BandPC itself)."""
    n = 20000
    A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (n, n)).tocsr()
    p = np.random.default_rng(0).permutation(n)
    for M in (A, A[p][:, p].tocsr()):
        reason, its, relres, ksp, _ = solve(M, np.random.default_rng(1).standard_normal(n))
        band = ksp.getPC().getPythonContext().setup.pc.getPythonContext().band
        assert reason > 0 and its <= 2 and relres <= 1e-8, (its, relres)
        assert "its graph is a chain" in lines(ksp) and "order, bandwidth" in lines(ksp)
        assert band.width <= 2 and band.nbytes <= 8 * 3 * n
    proc = _on_two_ranks(A, tmp_path / "chain.petsc")
    assert proc.returncode == 0 and "its graph is a chain" in proc.stdout, proc.stdout + proc.stderr
    assert "gathered and factored on each of the 2 ranks" in proc.stdout and "bandwidth 1" in proc.stdout, proc.stdout
    rng = np.random.default_rng(2)                   # a random graph of 3.2 entries a row: no chain, though the
    i, j = rng.integers(0, n, (2, 11 * n // 10))      # blocks of its random split over 2 ranks grow as slowly
    W = sp.csr_matrix((np.ones(i.size), (i, j)), (n, n))
    W = ((W + W.T) > 0).astype(float)
    W.setdiag(0.0)
    W.eliminate_zeros()
    L = (sp.diags(np.asarray(W.sum(axis=1)).ravel() + 1e-4) - W).tocsr()
    assert L.nnz / n <= sizing.CHAIN_ROW
    proc = _on_two_ranks(L, tmp_path / "random.petsc")
    assert proc.returncode == 0 and "its graph is a chain" not in proc.stdout, proc.stdout + proc.stderr


def test_rows_split_at_random_over_two_ranks_get_paired_leaves(tmp_path):
    """Rows in a random order split by PETSc over two ranks (half the couplings join the ranks): the two-level
    method pairs its aggregates even where rich rows with positive couplings (rotated anisotropy) would take standard
    leaves and the eig space, whose coarse operator then coupled each piece to leaves all over the other rank (310 s
    at 65 536 rows), and the anisotropy's ICC(0) is not tried on such blocks."""
    A, _ = CASES["aniso_e0.001_a45"](12000, 0)
    p = np.random.default_rng(0).permutation(A.shape[0])
    shuffled = sp.csr_matrix(A)[p][:, p].tocsr()
    mat = PETSc.Mat().createAIJ(shuffled.shape, csr=(shuffled.indptr.astype(PETSc.IntType),
                                                     shuffled.indices.astype(PETSc.IntType), shuffled.data),
                                comm=PETSc.COMM_SELF)
    viewer = PETSc.Viewer().createBinary(str(tmp_path / "shuffled.petsc"), "w", comm=PETSc.COMM_SELF)
    mat.view(viewer)
    viewer.destroy()
    for extra in ((), ("-htp_direct_max", "0")):       # as it comes: no ICC(0) either, whose trial on the blocks
        proc = _mpirun(2, EXAMPLE.parent / "matrix_file.py", "-f", str(tmp_path / "shuffled.petsc"), *HTPPC_FLAGS,
                       *extra)                          # passed (618 iterations at 65 536 rows, 269 two-level)
        assert proc.returncode == 0 and "second pass pairs" in proc.stdout, proc.stdout + proc.stderr
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        its = int(proc.stdout.split("iterations:")[1].split()[0])
        assert "coarse: const" in proc.stdout and relres <= 1.01e-8 and its <= 200, its


def test_shifted_rows_take_no_trial_past_the_whole_blocks_size(monkeypatch):
    """The shifted rows' trial factors each rank's whole block: past incomplete.WHOLE_NNZ stored entries it is not
    made, and the two-level method serves (the heat step above, the limit set below its entries)."""
    from petsc_htp.twolevel import incomplete

    A, b = meshes.p1_heat(3, 12000, 10.0)
    monkeypatch.setattr(incomplete, "WHOLE_NNZ", A.nnz - 1)
    reason, _, relres, ksp, _ = solve(A, b)
    assert reason > 0 and relres <= 1e-8 and "leaves: aggregation" in lines(ksp), lines(ksp)


def test_the_icc_trial_window_is_a_ball_of_the_graph():
    """The trial's rows on a large matrix: a graph ball of TRIAL_ROWS rows about the middle row, sorted (a square
    patch of a grid, not the strip of its leading rows), or about the next coupled row where the middle one is
    decoupled; the whole matrix where it is smaller."""
    from petsc_htp.twolevel import incomplete

    side = 301                                      # the middle row is the grid's centre
    path = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
    grid = sp.kronsum(path, path).tocsr()
    rows = incomplete.window(grid, 4000)
    assert rows.size == 4000 and np.all(np.diff(rows) > 0)
    x, y = rows % side, rows // side
    assert 80 < np.ptp(x) < 100 and 80 < np.ptp(y) < 100, (np.ptp(x), np.ptp(y))     # a diamond of radius ~45
    assert np.array_equal(incomplete.window(grid[:1000, :1000].tocsr(), 4000), np.arange(1000))
    apart = sp.block_diag([grid, sp.identity(3), grid]).tocsr()            # the middle row decoupled, then a grid
    rows = incomplete.window(apart, 4000)
    assert rows.size == 4000 and rows.min() >= grid.shape[0] + 3            # the ball grows in the next coupled part


def test_the_whole_graphs_growth_is_the_graph_shapes():
    """spread.global_growth (the balls of the whole graph over the ranks; here one) measures what graph_shape does: a
    2-D grid and a 3-D grid as meshes, a random graph above sizing.EXPANDER_GROWTH, its hub rows not grown through."""
    from petsc_htp.collective import Collective
    from petsc_htp.twolevel.graphshape import graph_shape
    from petsc_htp.twolevel.sizing import EXPANDER_GROWTH
    from petsc_htp.twolevel.spread import global_growth

    def growth(A):
        A = sp.csr_matrix(A)
        mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                  A.data), comm=PETSc.COMM_SELF)
        return global_growth(mat, A, Collective(mat.getComm())), graph_shape(A, want_weak=False, samples=8).growth

    path = sp.diags([-np.ones(39), 2 * np.ones(40), -np.ones(39)], [-1, 0, 1])
    grid2 = sp.kronsum(path, path)
    arrow = sp.bmat([[grid2, -np.ones((1600, 1))], [-np.ones((1, 1600)), np.array([[1600.0]])]])
    for A, low, high in ((grid2, 1.5, 1.8), (sp.kronsum(grid2, sp.diags([-np.ones(9), 2 * np.ones(10),
                                                                          -np.ones(9)], [-1, 0, 1])), 2.0, 2.8),
                         (arrow, 1.5, 1.8), (_random_graph(12000, 3), EXPANDER_GROWTH, 8.0)):
        whole, block = growth(A)
        assert low <= whole <= high and abs(whole - block) < 0.5, (whole, block)


def _dominant(A, c) -> sp.csr_matrix:
    """``A`` + c diag(sum_j |a_ij|, j != i) in ``A``'s pattern (its stored zeros kept): every coupled row diagonally
    dominant by at least the margin c."""
    off = np.asarray(abs(A).sum(axis=1)).ravel() - np.abs(A.diagonal())
    D = sp.csr_matrix(A, copy=True)
    D.setdiag(A.diagonal() + c * off)
    return D


def test_diagonally_dominant_rows_get_icc_of_the_whole_matrix_and_lose_it_with_their_dominance(tmp_path):
    """Above the small-matrix sizes a matrix whose coupled rows are all diagonally dominant by dominance.MARGIN or
    more (a mass matrix plus a time step's stiffness) takes ICC(0) of the whole matrix, and -ksp_view says why; the
    Dirichlet rows of a DMDA matrix (no couplings) do not count. New values of the same pattern that lose the
    dominance (the stiffness alone) make a new analysis, the banded factor's at this size, which values that regain it keep
    (no dominance test per frame). On two ranks ICC(0) of each rank's block (PCBJACOBI). The margin is that of the
    least dominant row."""
    from petsc_htp.twolevel.dominance import MARGIN, margin

    K, b = foreign.dmda(2, 110, 1e3, 0)
    assert margin(K, 0) < MARGIN <= margin(_dominant(K, 2 * MARGIN), 0) < 2 * MARGIN + 1e-12
    A = _dominant(K, 0.01)
    reason, its, relres, ksp, mat = solve(A, b)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and relres <= 1e-8 and its <= 60, its
    assert lines(ksp).startswith("whole matrix: ICC(0)") and "diagonally dominant" in lines(ksp)
    for values in (K, A):
        mat.setValuesCSR(values.indptr, values.indices, values.data)
        mat.assemble()
        reason, its, relres, _, _ = solve(values, b, mat=mat, ksp=ksp)
        assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == 2 and "banded Cholesky" in lines(ksp)
    proc = _on_two_ranks(A, tmp_path / "dominant.petsc")
    assert proc.returncode == 0 and "diagonally dominant" in proc.stdout, proc.stdout + proc.stderr
    assert "ICC(0) of each rank's diagonal block (PCBJACOBI)" in proc.stdout, proc.stdout


def test_a_dense_row_is_ordered_last_and_keeps_the_coarse_lu(tmp_path):
    """A constraint coupled to every row of a DMDA matrix (an SPD arrow matrix): Structure.dense, E = W^T A W by
    PETSc's 'rap' PtAP, the coarse LU ordered by nested dissection (QMD took 472 ms against 42 on such a 64k matrix,
    natural 331 s; METIS's order of the columns at any size) and kept at any size (GAMG's setup on it did not end at 1M rows), METIS's leaf order with the
    dense row's leaf last on one rank (on several PETSc's nested dissection of the gathered operator); CG converges
    in no more iterations than it takes without the row (give or take a few), on one rank and on two
    (examples/matrix_file.py)."""
    from petsc_htp.twolevel import coarseorder

    K, b = foreign.dmda(2, 110, 1e3, 0)
    v = -0.5 * np.random.default_rng(0).random(K.shape[0])
    A = sp.bmat([[K + sp.diags(np.abs(v)), v[:, None]], [v[None, :], np.array([[np.abs(v).sum() + 1.0]])]]).tocsr()
    A.sort_indices()
    reason, its, relres, ksp, _ = solve(A, np.append(b, 1.0))
    st = ksp.getPC().getPythonContext().analysis.st
    assert reason > 0 and relres <= 1e-8 and st.dense and ksp.getPC().getPythonContext().analysis.ops._rap
    its_K = solve(K, b, htp_direct_max="0")[1]                      # the two-level method, not its banded factor
    assert its <= its_K + 3 and not sizing.metis_ordered("lu", 2, 10 ** 6, 2, block=1, dense=True), (its, its_K)
    viewer = PETSc.Viewer().createASCII(str(tmp_path / "view.txt"), comm=PETSc.COMM_SELF)
    ksp.getPC().getPythonContext().setup.coarse.pc.view(viewer)
    viewer.destroy()
    text = (tmp_path / "view.txt").read_text()
    assert "type: lu" in text and "ordering: natural" in text and st.ordered       # the columns in METIS's order
    assert sizing.coarse_solver(2, 10 ** 6, dense=True) == "lu" != sizing.coarse_solver(2, 10 ** 6)
    assert sizing.metis_ordered("auto", 2, 10 ** 6, block=1, dense=True)
    order = coarseorder.leaf_order(st.lay, A)
    hub = st.lay.leaf[st.lay.iperm[A.shape[0] - 1]]                 # the dense row's leaf
    assert order[-1] == hub and sorted(order) == list(range(st.lay.leaves.n_leaves))
    proc = _on_two_ranks(A, tmp_path / "arrow.petsc")
    assert proc.returncode == 0 and "leaves: aggregation" in proc.stdout, proc.stdout + proc.stderr
    assert int(proc.stdout.split("iterations:")[1].split()[0]) <= its_K + 5, proc.stdout


def test_several_dense_rows_get_metis_order_at_any_coarse_size():
    """Three hubs, each coupled to a fifth of a 200^2 grid's rows (a shifted graph Laplacian): the coarse LU of 6 559
    rows is METIS-ordered with the hubs' leaves last, below the sizes where METIS pays otherwise (PETSc's nested
    dissection took it to an LU of 31 s, now 16 ms); its factor holds a few times E's entries."""
    side, rng = 200, np.random.default_rng(0)
    grid = sp.kronsum(*2 * [sp.diags([1.0, 1.0], [-1, 1], (side, side))]).tocoo()
    hubs = rng.choice(side * side, 3, replace=False)
    rows = np.concatenate([grid.row] + [np.full(side * side // 5, h) for h in hubs])
    cols = np.concatenate([grid.col] + [rng.choice(side * side, side * side // 5, replace=False) for _ in hubs])
    keep = rows != cols
    G = sp.coo_matrix((np.ones(keep.sum()), (rows[keep], cols[keep])), shape=(side * side,) * 2).tocsr()
    G = ((G + G.T) > 0).astype(float)
    A = (sp.diags(np.asarray(G.sum(axis=1)).ravel() + 0.01) - G).tocsr()
    A.sort_indices()
    b = np.random.default_rng(1).standard_normal(side * side)
    reason, its, relres, ksp, _ = solve(A, b, htp_variant="twolevel")
    setup = ksp.getPC().getPythonContext().setup
    assert reason > 0 and relres <= 1e-8 and setup.st.dense and setup.st.ordered, lines(ksp)
    factored = setup.coarse.pc.getFactorMatrix().getInfo()["nz_used"]
    assert factored <= 20 * setup.ops.E.getInfo()["nz_used"], (factored, setup.ops.E.getInfo()["nz_used"])
    for variant in ({}, {"htp_variant": "multilevel"}):     # a dense row keeps the two-level method (354 s before)
        reason, its, relres, ksp, _ = solve(A, b, **variant)
        assert reason > 0 and relres <= 1e-8 and ksp.getPC().getPythonContext().setup.st.dense, lines(ksp)
    assert "a dense row" in ksp.getPC().getPythonContext().variant.note


def test_the_margin_looks_at_a_sample_first_and_at_every_row_where_the_sample_passes():
    """dominance.margin on 22 500 rows: a matrix that is not dominant is told by a sample of rows; a dominant one by
    every row, so one interior row that keeps half its margin outside the sample is found, on any rank's block
    (``start``)."""
    from petsc_htp.twolevel.dominance import MARGIN, SAMPLE, margin

    K = foreign.dmda(2, 150, 1e3, 0)[0].tocsr()
    assert K.shape[0] > 4 * SAMPLE and margin(K, 0) < MARGIN
    D = _dominant(K, 0.01)
    assert abs(margin(D, 0) - 0.01) < 1e-9 and abs(margin(D[5000:], 5000) - 0.01) < 1e-9
    row = 75 * 150 + 76                                       # interior, not every (N // SAMPLE)-th
    assert row % (K.shape[0] // SAMPLE)
    diag = D.indptr[row] + np.flatnonzero(D.indices[D.indptr[row]:D.indptr[row + 1]] == row)[0]
    D.data[diag] = 0.5 * (D.data[diag] + K[row, row])          # half its margin: 0.005
    assert abs(margin(D, 0) - 0.005) < 1e-9 and abs(margin(D[5000:], 5000) - 0.005) < 1e-9


def test_wide_stencils_and_nodes_stay_meshes():
    """The graph of a 27-point 3-D stencil, and of the same with 3 unknowns per node (elasticity's pattern), grows as a
    mesh's, well below sizing.EXPANDER_GROWTH, so such matrices above the small sizes keep the two-level method."""
    from petsc_htp.twolevel.graphshape import graph_shape

    side = 22
    path = sp.diags([np.ones(side - 1), np.ones(side), np.ones(side - 1)], [-1, 0, 1])
    box = sp.kron(sp.kron(path, path), path).tocsr()                     # 27 points, 10 648 rows
    for A in (box, sp.kron(box, np.ones((3, 3))).tocsr()):
        assert graph_shape(A, want_weak=False, samples=8).growth < sizing.EXPANDER_GROWTH - 1


@pytest.mark.parametrize("n", [10000, 250000])
def test_new_leaves_when_a_severe_jump_moves_and_not_otherwise(n):
    """The same couplings scaled keep the leaves; a jump of 1e3 that moved keeps them too while the extra
    iterations cost less than an analysis (spacereuse.keeps_leaves); a jump of 1e8 that moved makes new leaves
    (Structure.jumped: at 1e10 old ones left CG to DIVERGED_DTOL). The weak couplings are counted on a sample of the rows
    (every k-th, Structure.stride: 1 up to WEAK_ROWS rows)."""
    from petsc_htp.twolevel.spacereuse import keeps_leaves

    side = int(round(n ** 0.5))
    A0, b = foreign.dmda(2, side, 1e3, 0)
    reason, its, _, ksp, mat = solve(A0, b, htp_direct_max="0")      # the two-level method at any size
    ctx = ksp.getPC().getPythonContext()
    assert ctx.analysis_count == 1 and reason > 0
    assert ctx.analysis.st.stride == max(1, A0.shape[0] // WEAK_ROWS)
    A0.data *= 2.0                                        # the same shape of the couplings: numeric step only
    mat.setValuesCSR(A0.indptr, A0.indices, A0.data)
    mat.assemble()
    reason, same_its, _, _, _ = solve(A0, b, mat=mat, ksp=ksp)
    assert reason > 0 and ctx.analysis_count == 1 and ctx.numeric_count == 2 and abs(same_its - its) <= 1
    A1, _ = foreign.dmda(2, side, 1e3, 1)                   # the inclusions moved, a mild jump
    assert ctx.analysis.st.moved(sp.csr_matrix(A1)) and not ctx.analysis.st.jumped(sp.csr_matrix(A1))
    mat.setValuesCSR(A1.indptr, A1.indices, A1.data)
    mat.assemble()
    reason, moved_its, relres, _, _ = solve(A1, b, mat=mat, ksp=ksp)
    kept = keeps_leaves(ctx.analysis.analysis_ms, [its, same_its], ctx.analysis.ms_per_it)
    assert reason > 0 and relres <= 1e-8 and ctx.analysis_count == (1 if kept else 2)
    for seed in (2, 3):                                     # a jump of 1e8 that moved: new leaves every time
        A2, _ = foreign.dmda(2, side, 1e8, seed)
        mat.setValuesCSR(A2.indptr, A2.indices, A2.data)
        mat.assemble()
        before = ctx.analysis_count
        reason, _, relres, _, _ = solve(A2, b, mat=mat, ksp=ksp)
        assert reason > 0 and ctx.analysis_count == before + 1, (reason, relres)


def test_kept_leaves_whose_couplings_moved_get_their_coarse_v_cycles_anew():
    """A 3-D DMDA frame whose inclusions moved keeps its leaves the first time (never measured what old ones cost),
    and the coarse GAMG V-cycles, which PETSc would keep with their interpolation for E's new values, coarsen E anew
    (CoarseSolve.renew): 34 CG iterations at 28^3 against 102 with the old interpolation."""
    A0, b = foreign.dmda(3, 28, 1e3, 0)
    reason, its, _, ksp, mat = solve(A0, b)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and ctx.analysis.coarse.pc.getType() == "gamg", lines(ksp)
    A1, _ = foreign.dmda(3, 28, 1e3, 1)
    mat.setValuesCSR(A1.indptr, A1.indices, A1.data)
    mat.assemble()
    reason, moved_its, relres, _, _ = solve(A1, b, mat=mat, ksp=ksp)
    assert ctx.analysis_count == 1 and ctx.numeric_count == 2 and not ctx.analysis.coarse.renew
    assert reason > 0 and relres <= 1e-8 and moved_its <= 40, (its, moved_its)


def test_a_coarse_graph_that_grows_as_no_mesh_takes_gamg_in_place_of_the_lu():
    """A 2-D grid (40 000 rows, + 0.01 I) with 1 % of its nodes joined at random: the matrix's sampled balls grow as a
    mesh's, so the LU was chosen for its coarse operator, whose whole graph grows as an expander's and whose LU
    filled 118-fold at 100 000 rows (7.9 s). E's growth from 32 seeds sends it to GAMG, and -ksp_view says why; the
    foreign study's 2-D coarse operators keep the LU (1.68-1.92)."""
    side, rng = 200, np.random.default_rng(11)
    grid = np.arange(side * side).reshape(side, side)
    a, c = rng.integers(0, side * side, (2, side * side // 100))
    rows = np.concatenate([grid[:-1].ravel(), grid[:, :-1].ravel(), a])
    cols = np.concatenate([grid[1:].ravel(), grid[:, 1:].ravel(), c])
    keep = rows != cols
    W = sp.csr_matrix((np.ones(keep.sum()), (rows[keep], cols[keep])), shape=(side * side,) * 2)
    W = W + W.T
    A = (sp.diags(np.asarray(W.sum(axis=1)).ravel() + 1e-2) - W).tocsr()
    reason, its, relres, ksp, _ = solve(A, np.random.default_rng(1).standard_normal(side * side),
                                        htp_variant="twolevel")
    text = lines(ksp)
    assert reason > 0 and relres <= 1e-8 and its <= 40, (reason, its, text)
    assert "GAMG" in text and "no 2-D mesh's: an LU would fill" in text, text
    A0, b = foreign.dmda(2, 200, 1e3, 0)
    assert "coarse solve: LU" in lines(solve(A0, b, htp_variant="twolevel")[3])


def _cells(k):
    """The 5-point finite-volume matrix of cell conductivities ``k`` (n x n), harmonic faces, Dirichlet walls."""
    n = k.shape[0]
    i = np.arange(n * n).reshape(n, n)
    kx, ky = 2 * k[:-1] * k[1:] / (k[:-1] + k[1:]), 2 * k[:, :-1] * k[:, 1:] / (k[:, :-1] + k[:, 1:])
    off = sp.coo_matrix((np.concatenate([kx.ravel(), ky.ravel()]),
                         (np.concatenate([i[:-1].ravel(), i[:, :-1].ravel()]),
                          np.concatenate([i[1:].ravel(), i[:, 1:].ravel()]))), shape=(n * n,) * 2)
    off = (off + off.T).tocsr()
    wall = 2 * (k * np.pad(np.zeros((n - 2, n - 2)), 1, constant_values=1.0)).ravel()   # Dirichlet faces, corners 1x
    return (sp.diags(np.asarray(off.sum(axis=1)).ravel() + wall) - off).tocsr()


def test_two_value_sets_in_turn_make_new_leaves_once_old_ones_cost_more():
    """One KSP, two unrelated value sets of one pattern in turn (a smooth field of contrast 1e6, a cell-wise random
    one of 10^U(-3, 3)): the first random frame on the smooth field's leaves takes hundreds of iterations; the leaves
    are then judged by the worst solve with them, not the last (a smooth frame's), so the next random frame gets new
    leaves and a fresh solve's iterations (it kept the old ones and took 707 at 65 536 rows)."""
    n = 128
    x = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x, x, indexing="ij")
    smooth = _cells(1e6 ** ((np.sin(2 * np.pi * X) * np.sin(3 * np.pi * Y) + np.cos(5 * np.pi * X * Y) + 2) / 4))
    rough = _cells(10 ** np.random.default_rng(8).uniform(-3, 3, (n, n)))
    b = np.random.default_rng(1).standard_normal(n * n)
    fresh = solve(rough, b)[1]
    _, its, _, ksp, mat = solve(smooth, b)
    found = []
    for A in (rough, smooth, rough):
        mat.setValuesCSR(A.indptr, A.indices, A.data)
        mat.assemble()
        reason, its, relres, _, _ = solve(A, b, mat=mat, ksp=ksp)
        assert reason > 0 and relres <= 1e-8
        found.append(its)
    assert found[0] > 3 * fresh and found[2] <= fresh + 5, (fresh, found)


def test_leaves_are_kept_while_a_new_analysis_would_not_pay():
    """keeps_leaves: extra iterations keep them while they cost no more than the analysis took; after one solve,
    what old leaves cost the last time values moved decides (never measured: they are tried)."""
    from petsc_htp.twolevel.spacereuse import keeps_leaves

    assert keeps_leaves(40.0, [], 2.0) and keeps_leaves(40.0, [30], 2.0)
    assert keeps_leaves(40.0, [30, 50], 2.0) and not keeps_leaves(40.0, [30, 51], 2.0)
    assert keeps_leaves(40.0, [30], 2.0, penalty=40.0) and not keeps_leaves(40.0, [30], 2.0, penalty=41.0)


# ------------------------------------------------------------------ the study

def test_foreign_study_quick(tmp_path):
    out = tmp_path / "foreign"
    assert main(["--quick", "--out", str(out), "--studies", "foreign", "--methods", "cg_htp", "cg_icc", "amgcl_ce500",
                 "cg_gamg_default", "gamg_t0.05_a0", "--foreign-cases", "dmda2d", "free_surface", "--threads", "1",
                 "--no-progress"]) == 0
    rows = store.read_jsonl(store.study_path(out, "foreign"))
    single = [r for r in rows if r["mode"] == "single"]
    assert {(r["case"], r["method"]) for r in single} >= {("dmda2d", "cg_htp"), ("free_surface", "amgcl_ce500")}
    assert all(r["ok"] and r["relres_proj"] <= 1e-7 for r in rows if r["method"] != "cg_icc"), \
        [r for r in rows if not r["ok"]]
    seq = [r for r in rows if r["mode"] == "sequence" and r["case"] == "free_surface"]
    assert len({r["n"] for r in seq if r["method"] == "cg_htp"}) == 2    # the liquid moved: new patterns
    fresh = {(r["case"], r["method"]): r for r in rows if r["mode"] == "fresh"}
    assert set(fresh) == {(c, m) for c in ("dmda2d", "free_surface")
                          for m in ("cg_htp", "cg_icc", "amgcl_ce500", "cg_gamg_default", "gamg_t0.05_a0")}
    assert all(r["ok"] and r["peak_rss_mb"] >= r["baseline_mb"] > 0 and r["import_ms"] > 0 for r in fresh.values())
    report = (out / "report.md").read_text()
    assert "## Matrices from other programs" in report and "first call of a fresh Python process" in report
    assert (out / "foreign.png").stat().st_size > 0
    best = report[report.index("its default and its best swept setting, single"):]
    head, _, first = best.split("\n")[2:5]
    assert head.split(" | ")[:6] == ["| case", "N", "cg_htp", "GAMG default", "GAMG best", "cg_htp / GAMG best"], head
    assert "AMGCL default | AMGCL best" in head and first.startswith("| dmda2d |"), best
    cols = first.split(" | ")
    assert cols[4].endswith(("cg_gamg_default", "gamg_t0.05_a0")) and cols[6] == "not run", first   # amgcl itself: not run
    assert cols[7].endswith("amgcl_ce500"), first


HTPPC_FLAGS = ("-ksp_type", "cg", "-ksp_rtol", "1e-8", "-ksp_norm_type", "unpreconditioned", "-pc_type", "python",
               "-pc_python_type", "petsc_htp.HTPPC", "-ksp_view")


def _mpirun(ranks, script, *args):
    """``mpiexec -n ranks python script args``: the finished process (stdout, stderr as text)."""
    import shutil
    import subprocess
    import sys

    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin:/usr/local/bin")
    assert mpiexec, "mpiexec not found (the Makefile installs MPICH)"
    return subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(script), *args], capture_output=True,
                          text=True, timeout=300)


@pytest.mark.parametrize("ranks", [1, 2])
def test_the_dmda_example_runs_with_htppc_from_the_command_line(ranks):
    """examples/dmda_poisson.py: a plain PETSc DMDA program, HTPPC's two-level method chosen by options only, on 1 and
    2 ranks (each rank aggregates its own rows). With standard second passes and the eig space each rank orders its
    own leaves' coarse columns by METIS, those coupled to the other rank last (360^2: about 13 700 coarse rows in
    blocks of 2); the default's paired aggregates with one column each are ordered by PETSc's factor alone."""
    for flags, metis in ((("-htp_aggregation", "standard"), True), ((), False)):
        proc = _mpirun(ranks, EXAMPLE, "-n", "360", *HTPPC_FLAGS, "-htp_variant", "twolevel", *flags)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert f"{ranks} MPI process" in proc.stdout
        its = int(proc.stdout.split("iterations:")[1].split()[0])
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        assert its <= 40 and relres <= 1.01e-8 and "leaves: aggregation" in proc.stdout and "graph: 2-D" in proc.stdout
        assert ("coarse columns in METIS's nested-dissection order" in proc.stdout) == metis, proc.stdout
        assert ("LU on each of the 2 ranks (redundant)" in proc.stdout) == (ranks == 2), proc.stdout
        assert f"second pass {'standard' if metis else 'pairs'}" in proc.stdout, proc.stdout
        assert ("ranks: 2; 0." in proc.stdout) == (ranks == 2) and "WARNING" not in proc.stdout, proc.stdout  # strips


def test_the_matrix_file_example_loads_what_it_wrote_on_two_ranks(tmp_path):
    """examples/matrix_file.py, PETSc's ex10 pattern: a foreign-study case (P1 triangles, nodes at random) written to a
    PETSc binary file on two ranks and loaded again with MatLoad; HTPPC by options alone solves both the same way, and
    the no-flux case gets the constant null space attached. The nodes' random numbering cuts half the couplings
    between the ranks: -ksp_view says so, with advice (:mod:`petsc_htp.ranksplit`), and names the gathered factor
    an option asks for."""
    path = tmp_path / "tri.petsc"
    script = EXAMPLE.parent / "matrix_file.py"
    flags = (*HTPPC_FLAGS, "-htp_direct_max", "0")        # the two-level method (not the gathered ICC(0))
    runs = [_mpirun(2, script, "-case", "fem_tri", "-n", "6000", "-write", str(path), *flags),
            _mpirun(2, script, "-f", str(path), *flags)]
    found = []
    for proc in runs:
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "on 2 rank(s)" in proc.stdout and "2 MPI process" in proc.stdout
        its = int(proc.stdout.split("iterations:")[1].split()[0])
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        assert its <= 40 and relres <= 1.01e-8, proc.stdout
        assert "of the off-diagonal couplings join rows of two ranks" in proc.stdout, proc.stdout
        assert "WARNING: leaves hold one rank's rows, so a split that cuts this many" in proc.stdout, proc.stdout
        found.append(its)
    assert found[0] == found[1]
    small = _mpirun(2, script, "-case", "fem_tri", "-n", "2000", *HTPPC_FLAGS)    # the gathered factor: no leaves
    assert small.returncode == 0 and "gathered and factored on each of the 2 ranks" in small.stdout, small.stdout
    assert "join rows of two ranks" not in small.stdout, small.stdout
    asked = _mpirun(2, script, "-case", "fem_tri", "-n", "2000", *HTPPC_FLAGS, "-htp_leaf_redundant_pc_type", "cholesky")
    want = "whole matrix: PETSc's cholesky, as -htp_leaf_redundant_pc_type asks"
    assert asked.returncode == 0 and want in asked.stdout, asked.stdout
    proc = _mpirun(2, script, "-case", "neumann", "-n", "4096", *HTPPC_FLAGS)
    assert proc.returncode == 0 and "constant null space attached" in proc.stdout, proc.stdout + proc.stderr


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_large_2d_coarse_operator_on_two_ranks_gets_distributed_v_cycles_in_the_deflated_form(ranks):
    """In 2-D on several ranks a coarse operator above sizing.COARSE_REDUNDANT_MAX rows (440^2: about 20 000) is
    not factored on every rank: two GAMG V-cycles an application, exact enough for the deflated form (CG converges
    to the true residual's tolerance); on one rank the LU stays."""
    from petsc_htp.twolevel import sizing

    assert sizing.coarse_solver(2, 20000, 2) == "gamg" and sizing.coarse_solver(2, 20000, 1) == "lu"
    assert sizing.coarse_solver(2, 16000, 2) == "lu" and sizing.coarse_exact(2, "gamg")
    assert sizing.coarse_solver(2, 65536, 2, "morton") == "lu"          # own frames: the LU, 22 against 34 its
    assert sizing.coarse_exact(3, "gamg") and not sizing.coarse_exact(3, "gamg", near=6)     # paired: two V-cycles
    assert sizing.coarse_exact(3, "gamg", "morton") and sizing.coarse_exact(2, "lu")
    proc = _mpirun(ranks, EXAMPLE, "-n", "440", *HTPPC_FLAGS, "-htp_variant", "twolevel")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    its = int(proc.stdout.split("iterations:")[1].split()[0])
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert relres <= 1.01e-8 and its <= (50 if ranks == 2 else 40), proc.stdout
    assert ("two GAMG V-cycles" in proc.stdout) == (ranks == 2) and "form: deflated" in proc.stdout, proc.stdout


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_row_scaled_operator_takes_scaled_piece_vectors(ranks):
    """examples/dmda_poisson.py -scale_rows 2: D A D with D in 1e-2 .. 1e2 per row, whose near null space is D^-1 1:
    the pieces take |diag|^-1/2 (the quotients summed over the ranks) and CG keeps its iterations (389 with the piece
    constants at 200^2); the unscaled operator keeps its constants."""
    for flags, scaled in ((("-scale_rows", "2"), True), ((), False)):
        proc = _mpirun(ranks, EXAMPLE, "-n", "120", "-contrast", "1", *flags, *HTPPC_FLAGS)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        its = int(proc.stdout.split("iterations:")[1].split()[0])
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        assert its <= 40 and relres <= 1.01e-8, proc.stdout
        assert ("pieces take |diag|^-1/2 in place of their constants" in proc.stdout) == scaled, proc.stdout


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_row_scaled_operator_weights_the_v_cycles_leaf_vectors(ranks):
    """examples/dmda_poisson.py -scale_rows 2 at 200^2 (the V-cycles' size): the finest leaf vectors take
    |diag|^-1/2 (CG had taken 686-776 iterations at 256^2 on the leaf constants), the unscaled operator keeps its
    constants."""
    for flags, scaled in ((("-scale_rows", "2"), True), ((), False)):
        proc = _mpirun(ranks, EXAMPLE, "-n", "200", "-contrast", "1", *flags, *HTPPC_FLAGS)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        its = int(proc.stdout.split("iterations:")[1].split()[0])
        relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
        assert its <= 30 and relres <= 1.01e-8 and "multilevel V-cycles" in proc.stdout, proc.stdout
        assert ("leaf constants weighted by |diag|^-1/2" in proc.stdout) == scaled, proc.stdout


def test_the_neighbours_diagonals_tell_a_row_scaling_from_coefficient_jumps():
    """scaling.neighbours_spread: D A D (D = 10^U(-s, s), s from 0.5) passes, the foreign study's matrices (jumps,
    Neumann, triangles, tetrahedra; a log-normal field of 4 096 rows varies enough between neighbours to pass, and the
    quotients then keep its constants) do not; read from about SPREAD_ROWS rows and one neighbour each."""
    from petsc_htp.collective import Collective
    from petsc_htp.twolevel import scaling

    coll = Collective(PETSc.COMM_SELF)
    for case in ("dmda2d", "lognormal", "neumann", "fem_tri", "fem_tet"):
        A = CASES[case](4096, 0)[0].tocsr()
        assert scaling.neighbours_spread(A, 0, coll) == (case == "lognormal"), case
        for s in (0.5, 2.0):
            d = 10.0 ** np.random.default_rng(1).uniform(-s, s, A.shape[0])
            assert scaling.neighbours_spread((sp.diags(d) @ A @ sp.diags(d)).tocsr(), 0, coll), (case, s)


def test_scaling_quotients_tell_the_smoother_piece_vector():
    """scaling.weights: z = |diag|^-1/2 where D A D makes it far smoother than the constant; None for A itself, for
    coefficient jumps (z rough across them) and for a singular Neumann matrix (the constant's quotient is 0)."""
    from petsc_htp.collective import Collective
    from petsc_htp.twolevel import scaling

    coll = Collective(PETSc.COMM_SELF)
    A, _ = foreign.dmda(2, 60)
    d = 10.0 ** np.random.default_rng(0).uniform(-2, 2, A.shape[0])
    z, (one, rough) = scaling.weights((sp.diags(d) @ A @ sp.diags(d)).tocsr(), 0, coll)
    assert z is not None and rough < scaling.RATIO * one
    ratio = z * d
    coupled = ~decoupled_rows(A)
    assert np.ptp(ratio[coupled & (np.abs(A.diagonal()) == 4)]) < 1e-12       # z is D^-1 1 where A's diagonal is 4
    for M in (A, CASES["lognormal"](3600, 0)[0], CASES["neumann"](3600, 0)[0]):
        assert scaling.weights(M, 0, coll)[0] is None


@pytest.mark.parametrize("ranks", [1, 2])
def test_the_dmda_example_assembles_its_operator_on_every_rank_and_solves_frames(ranks):
    """examples/dmda_poisson.py -dim 3: each rank sets its own rows by whole arrays (:mod:`petsc_htp.scenes.dmda`: the
    balls' 7-point stencil, and in 2-D the discs' 5-point one, in natural order, also after new values of another
    seed, checked by a product on every rank: tests/dmda_case.py), and HTPPC solves it from the command line, the
    graph read as 3-D, then a second frame (``-frames 1``: the next seed's balls in the same Mat and KSP)."""
    for dim in ("2", "3"):
        proc = _mpirun(ranks, Path(__file__).parent / "dmda_case.py", dim)
        assert proc.returncode == 0 and proc.stdout.count("same operator") == ranks, proc.stdout + proc.stderr
    proc = _mpirun(ranks, EXAMPLE, "-dim", "3", "-n", "24", "-frames", "1", *HTPPC_FLAGS)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    relres = float(proc.stdout.split("||b - A x|| / ||b||:")[1].split()[0])
    assert relres <= 1.01e-8 and "graph: 3-D" in proc.stdout and f"{ranks} MPI process" in proc.stdout
    later = proc.stdout.split("frame 1: ")[1].splitlines()[0]           # new values, the same Mat and KSP
    assert "converged reason 2" in later and float(later.split("true relative residual ")[1]) <= 1e-7, later


def test_amg_coarse_solve_of_3d_aggregation_leaves_is_two_v_cycles_deflated_or_one_balanced():
    """On the 3-D coarse operator of paired aggregation leaves GAMG is two V-cycles an application, exact enough for
    the deflated form: the outer iterations stay near those of the coarse LU. One V-cycle (set by options) is taken
    by the balanced form (SPD with a convergent coarse solve); the deflated form with that V-cycle takes more."""
    A, b = CASES["dmda3d"](27000, 0)
    _, lu_its, _, _, _ = solve(A, b, htp_coarse_solver="lu")
    reason, its, relres, ksp, _ = solve(A, b, htp_coarse_solver="gamg")
    assert reason > 0 and relres <= 1e-8 and its <= min(lu_its + 3, 40), (its, lu_its)
    text = lines(ksp)
    assert "coarse solve: two GAMG V-cycles" in text and "form: deflated" in text, text
    assert ksp.getPC().getPythonContext().setup.coarse.pc.getType() == "gamg"
    one = {"htp_coarse_solver": "gamg", "htp_cs_pc_mg_multiplicative_cycles": "1"}
    reason, one_its, relres, ksp, _ = solve(A, b, **one)
    assert reason > 0 and relres <= 1e-8 and one_its <= min(lu_its + 6, 40), (one_its, lu_its)
    text = lines(ksp)
    assert "coarse solve: one GAMG V-cycle" in text and "form: balanced" in text, text
    _, deflated_its, _, _, _ = solve(A, b, htp_form="deflated", **one)
    assert deflated_its > one_its, (deflated_its, one_its)


def test_the_partition_line_warns_where_the_split_cuts_many_couplings():
    """-ksp_view's partition line (:mod:`petsc_htp.ranksplit`): none on one rank, the shares on several, and advice
    above CUT_ADVICE only."""
    from petsc_htp.ranksplit import CUT_ADVICE, describe

    assert describe(None) == []
    good, = describe((2, 0.002, 0.003))
    assert good.startswith("ranks: 2; 0.2% of the off-diagonal couplings") and "at most 0.3%" in good
    assert "WARNING" not in good
    bad, = describe((4, CUT_ADVICE + 0.01, 0.5))
    assert "ranks: 4; 21.0%" in bad and "WARNING: leaves hold one rank's rows" in bad and "at most 50.0%" in bad


def _frames_on_one_ksp(frames, prefix, extra=()):
    """Solve each (A, b) of ``frames`` on one KSP (a new Mat each, KSPReset where the size changed, one
    KSPSetFromOptions) under ``prefix`` with HTPPC (``extra``: more options); each frame's (reason, variant note,
    setup)."""
    from bad_input_cases import htp_ksp

    ksp, mats, out = htp_ksp(prefix, PETSc.COMM_SELF), [], []
    try:
        for k, v in extra:
            PETSc.Options(prefix).setValue(k, v)
        for k, (A, b) in enumerate(frames):
            frame = bare_frame(A, b, "")
            mats.append(frame_mat(frame, PETSc.COMM_SELF))
            if k and mats[-1].getSize() != mats[-2].getSize():
                ksp.reset()
            ksp.setOperators(mats[-1], mats[-1])
            if not k:
                ksp.setFromOptions()
            rhs = frame_vec(frame, mats[-1])
            ksp.solve(rhs, rhs.duplicate())
            ctx = ksp.getPC().getPythonContext()
            out.append((ksp.getConvergedReason(), ctx.variant.note, ctx.setup))
    finally:
        for obj in [ksp] + mats:
            obj.destroy()
        for k in ("ksp_type", "ksp_norm_type", "ksp_rtol", "pc_type", "pc_python_type", *(k for k, _ in extra)):
            PETSc.Options(prefix).delValue(k)
    return out


def test_a_new_pattern_of_the_same_sizes_keeps_the_whole_matrix_choice():
    """A liquid's frames on one KSP (a new Mat each frame, KSPReset where its size changed, no second
    KSPSetFromOptions): the second frame keeps the first's choice of no whole factor and -ksp_view says so; a matrix
    of other sizes (a chain) chooses afresh (its banded factor); so does a frame under -htp_direct_max that crosses
    it (9 216 rows after 10 000: Cholesky, as the option says), and a rank without rows on 2 ranks
    (tests/keptchoice_case.py: a whole factor, where the kept choice had hung)."""
    import shutil
    import subprocess
    import sys

    chain = sp.diags([-np.ones(19_999), 2.0 * np.ones(20_000), -np.ones(19_999)], [-1, 0, 1], format="csr")
    out = _frames_on_one_ksp([CASES["free_surface"](32768, 0), CASES["free_surface"](32768, 1),
                              (chain, np.ones(20_000))], "keep_")
    assert all(reason > 0 for reason, _, _ in out), out
    assert "kept" not in out[0][1] and "the whole-matrix choice kept from the last pattern" in out[1][1], out
    assert "kept" not in out[2][1] and getattr(out[2][2], "kind", None) == "band", out
    out = _frames_on_one_ksp([CASES["dmda2d"](10_000, 0), CASES["dmda2d"](9216, 0)], "keepmax_",
                             [("htp_direct_max", "9500")])
    assert "kept" not in out[1][1] and getattr(out[1][2], "kind", None) == "cholesky", out
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    proc = subprocess.run([mpiexec, "-n", "2", sys.executable, str(Path(__file__).parent / "keptchoice_case.py")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.split() == ["0", "2", "MultilevelPC", "False", "1", "2", "DirectPC", "False"], proc.stdout
