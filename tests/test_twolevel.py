"""Tests for the two-level preconditioner core (petsc_htp.twolevel.leaves, petsc_htp.twolevel)."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from scipy.sparse.csgraph import connected_components

from petsc_htp.sim.flow import Flow
from petsc_htp.twolevel.leaves import Leaves, choose_leaves, contiguous_leaves, metis_leaves, morton_leaves
from petsc_htp.morton import quantized_morton_codes
from petsc_htp.training.pcg import jacobi, pcg
from petsc_htp.scenes.generator import make_frame
from petsc_htp.twolevel.batched import analyse, factor

SEED = 1_000_000          # the first held-out benchmark frame


def setup(A, leaves, **kw):
    """analyse + factor in one go."""
    return factor(analyse(A, leaves), A, **kw)


def dense_operator(pre):
    """M assembled column by column through ``apply``."""
    return np.column_stack([pre.apply(e) for e in np.eye(pre.n)])


def dense_reference(A, leaves, P):
    """Q + (I - QA) B (I - AQ) from dense numpy, with Q = P pinv(P^T A P) P^T."""
    A = A.toarray()
    B = np.zeros_like(A)
    for lo, hi in zip(leaves.offsets[:-1], leaves.offsets[1:]):
        rows = leaves.perm[lo:hi]
        B[np.ix_(rows, rows)] = np.linalg.inv(A[np.ix_(rows, rows)])
    Q = P @ np.linalg.pinv(P.T @ A @ P, rtol=1e-10, hermitian=True) @ P.T
    I = np.eye(len(A))
    return Q + (I - Q @ A) @ B @ (I - A @ Q)


def leaf_basis(leaves, basis):
    """A padded (K, Lmax, r) basis as a dense (N, K r) matrix in the caller's row order."""
    K, L, r = basis.shape
    P = np.zeros((leaves.n, K * r))
    for k, (lo, hi) in enumerate(zip(leaves.offsets[:-1], leaves.offsets[1:])):
        P[leaves.perm[lo:hi], k * r:(k + 1) * r] = basis[k, :hi - lo]
    return P


def laplacian_3d(side):
    """7-point Laplacian with Dirichlet boundaries on a side^3 grid (SPD)."""
    t = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
    eye = sp.identity(side)
    return sp.csr_matrix(sp.kron(sp.kron(t, eye), eye) + sp.kron(sp.kron(eye, t), eye)
                         + sp.kron(sp.kron(eye, eye), t))


def fem_matrix(n, seed=0, sigma=1.0):
    """P1 FEM stiffness on a random Delaunay mesh, lognormal element coefficients, Dirichlet hull.

    Not an M-matrix (obtuse triangles give positive couplings); boundary rows are identity rows.
    """
    rng = np.random.default_rng(seed)
    pts = rng.random((n, 2))
    tri = Delaunay(pts)
    rows, cols, vals = [], [], []
    for simplex, coef in zip(tri.simplices, np.exp(rng.normal(0.0, sigma, len(tri.simplices)))):
        T = np.column_stack((np.ones(3), pts[simplex]))
        grads = np.linalg.inv(T)[1:]
        area = abs(np.linalg.det(T)) / 2
        rows.append(np.repeat(simplex, 3))
        cols.append(np.tile(simplex, 3))
        vals.append((coef * area * grads.T @ grads).ravel())
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    keep = np.ones(n)
    keep[np.unique(tri.convex_hull)] = 0.0
    D = sp.diags(keep)
    return sp.csr_matrix(D @ A @ D + sp.diags(1.0 - keep))


# ------------------------------------------------------------------------- leaves

def test_contiguous_leaves_cover_rows_evenly():
    lv = contiguous_leaves(1000, leaf=128)
    assert lv.n == 1000 and lv.n_leaves == 8
    assert lv.sizes.min() >= 124 and lv.max_size == 125
    assert np.array_equal(lv.perm, np.arange(1000))


def pieces(A, lv):
    """Connected components of every leaf's block."""
    return [connected_components(A[r][:, r], directed=False)[0]
            for r in (lv.perm[lo:hi] for lo, hi in zip(lv.offsets[:-1], lv.offsets[1:]))]


def test_morton_leaves_are_quadtree_blocks():
    fr = make_frame(4096, SEED)                        # a full 64 x 64 grid: the 128-cell blocks
    lv = choose_leaves(fr.A, fr.coords)
    assert np.array_equal(lv.offsets, contiguous_leaves(4096, leaf=128).offsets)
    flow = Flow(128, 128)                              # an obstacle: plain chunks straddle blocks
    A = flow.system()[0].tocsr()
    lv, plain = choose_leaves(A, flow.coords), contiguous_leaves(A.shape[0], leaf=128)
    assert lv.sizes.min() >= 96 and lv.max_size <= 160
    assert sum(c > 1 for c in pieces(A, lv)) <= 2 < 20 < sum(c > 1 for c in pieces(A, plain))
    with pytest.raises(ValueError, match="non-decreasing"):
        morton_leaves(quantized_morton_codes(flow.coords)[::-1].astype(np.int64))


def test_metis_leaves_are_deterministic_parts_of_the_graph():
    fr = make_frame(4096, SEED)
    a, b = metis_leaves(fr.A, leaf=128), metis_leaves(fr.A, leaf=128)
    assert np.array_equal(a.perm, b.perm) and np.array_equal(a.offsets, b.offsets)
    assert np.array_equal(np.sort(a.perm), np.arange(4096))
    assert a.n_leaves == 32 and 100 <= a.sizes.min() and a.max_size <= 140
    cut = sum(np.isin(fr.A[a.perm[lo:hi]].indices, a.perm[lo:hi], invert=True).sum()
              for lo, hi in zip(a.offsets[:-1], a.offsets[1:]))
    assert cut < 0.1 * fr.A.nnz


def test_choose_leaves_layouts():
    fr = make_frame(1024, SEED)
    assert choose_leaves(fr.A, fr.coords).kind == "morton (given)"
    assert choose_leaves(fr.A).kind == "aggregation" and choose_leaves(fr.A, layout="graph").kind == "graph"
    assert choose_leaves(fr.A, layout="metis").kind == "metis"
    assert choose_leaves(laplacian_3d(12), layout="graph").kind == "metis"        # not 2-D-like: METIS
    assert choose_leaves(fr.A, layout="rcm").kind == "rcm"
    assert choose_leaves(fr.A, layout="natural", leaf=100).n_leaves == 11
    with pytest.raises(ValueError, match="layout"):
        choose_leaves(fr.A, layout="hilbert")
    with pytest.raises(ValueError, match="coord"):
        choose_leaves(fr.A, layout="morton")
    with pytest.raises(ValueError, match="leaf"):
        choose_leaves(fr.A, layout="graph", leaf=0)
    with pytest.raises(ValueError, match="permutation"):
        Leaves(np.zeros(4, dtype=np.int64), np.array([0, 4]), "bad")


# ------------------------------------------------------------------ the operator

@pytest.mark.parametrize("singular", [False, True])
def test_matches_dense_formula_and_is_spd(singular):
    fr = make_frame(256, SEED)
    A = fr.A if singular else sp.csr_matrix(fr.A + sp.diags(np.linspace(0, 0.1, 256)))
    lv = choose_leaves(A, fr.coords, leaf=32)
    basis = np.random.default_rng(0).standard_normal((lv.n_leaves, 32, 3))
    basis[:, :, 0] = 1.0                          # leaf constants in the span: A_c is singular too
    pre = setup(A, lv, coarse="given", basis=basis)
    M = dense_operator(pre)
    ref = dense_reference(A, lv, leaf_basis(lv, basis))
    proj = np.eye(256) - np.ones((256, 256)) / 256 if singular else np.eye(256)
    assert np.abs(proj @ (M - ref) @ proj).max() <= 1e-9 * np.abs(ref).max()
    assert np.abs(M - M.T).max() <= 1e-13 * np.abs(M).max()
    assert np.linalg.eigvalsh(M).min() > 0
    assert pre.coarse_note == "" and pre.null_components == int(singular)


def test_eig_basis_approximates_the_low_neumann_modes():
    """Each leaf: one Neumann-step vector orthogonal to its constant, then the constant (the first leaf's left out:
    A's constant null space), together close to the two lowest Neumann eigenvectors."""
    fr = make_frame(1024, SEED)
    lv = choose_leaves(fr.A, fr.coords)
    pre = setup(fr.A, lv, coarse="eig", rank=2)
    A = fr.A.toarray()
    P = pre.basis.numpy()
    for k, (lo, hi) in enumerate(zip(lv.offsets[:-1], lv.offsets[1:])):
        rows = lv.perm[lo:hi]
        N = A[np.ix_(rows, rows)]
        N += np.diag(A[rows].sum(1) - N.sum(1))                 # off-leaf couplings onto the diagonal
        w, V = np.linalg.eigh(N)
        const = np.full(hi - lo, 1 / np.sqrt(hi - lo))
        assert np.allclose(P[k, :hi - lo, 1], 0.0 if k == 0 else const, atol=1e-12)
        mode = P[k, :hi - lo, 0]
        assert abs(mode @ mode - 1) < 1e-12 and abs(mode @ const) < 1e-12
        both = np.column_stack([mode, const])                    # one inverse-iteration step and the constant
        assert np.linalg.eigvalsh(both.T @ N @ both)[-1] <= 1.5 * w[1], (k, w[:2])


def test_iterations_far_below_jacobi():
    for n in (1024, 4096):
        fr = make_frame(n, SEED)
        an = analyse(fr.A, choose_leaves(fr.A, fr.coords))
        its = {c: pcg(fr.A, fr.b, factor(an, fr.A, coarse=c, rank=4).apply, 1e-8) for c in ("eig", "const")}
        jac = pcg(fr.A, fr.b, jacobi(fr.A), 1e-8).iterations
        assert all(res.converged for res in its.values())
        assert its["eig"].iterations <= 30 and its["const"].iterations <= 55
        assert its["const"].iterations < jac / 3 and its["eig"].iterations < jac / 5


@pytest.mark.parametrize("layout", ["auto", "metis"])
def test_leaves_of_a_shuffled_matrix_meet_the_iteration_bar(layout):
    """A bare shuffled matrix: aggregation leaves follow its couplings (Morton's iterations), METIS parts come close."""
    fr = make_frame(4096, SEED)
    q = np.random.default_rng(1).permutation(4096)
    A, b = sp.csr_matrix(fr.A[q][:, q]), fr.b[q]
    lv = choose_leaves(A, layout=layout)
    assert lv.kind == ("aggregation" if layout == "auto" else "metis")
    shuffled = pcg(A, b, setup(A, lv).apply, 1e-8).iterations
    morton = pcg(fr.A, fr.b, setup(fr.A, choose_leaves(fr.A, fr.coords)).apply, 1e-8).iterations
    assert shuffled <= 35 and morton <= 35 and morton <= shuffled + (2 if layout == "auto" else 0)


@pytest.mark.parametrize("name", ["laplacian_3d", "fem"])
def test_other_operator_families(name):
    A = laplacian_3d(14) if name == "laplacian_3d" else fem_matrix(2500, sigma=0.5)
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    pre = setup(A, choose_leaves(A), coarse="eig", rank=4)
    res = pcg(A, b, pre.apply, 1e-8)
    jac = pcg(A, b, jacobi(A), 1e-8)
    assert res.converged and jac.converged
    assert res.iterations <= 35 and res.iterations < jac.iterations / 2.5


def path_laplacian(m):
    """Neumann Laplacian of a path of m cells (singular)."""
    return sp.diags([-np.ones(m - 1), np.r_[1.0, 2.0 * np.ones(m - 2), 1.0], -np.ones(m - 1)], [-1, 0, 1])


def check_disconnected(A, b, lv, null):
    """M finite, bounded, symmetric, every null component's constant left out (no shifts); PCG converges."""
    for coarse in ("const", "eig"):
        pre = setup(A, lv, coarse=coarse, rank=2)
        M = dense_operator(pre)
        assert np.all(np.isfinite(M)) and np.abs(M).max() < 1e3
        assert np.abs(M - M.T).max() <= 1e-12 * np.abs(M).max()
        assert pre.null_components == null and pre.coarse_note == "" and pre.leaf_note == ""
        res = pcg(A, b, pre.apply, 1e-8)
        assert res.converged and res.iterations <= 40
        assert np.linalg.norm(A @ res.x - b) <= 1e-7 * np.linalg.norm(b)


def consistent(b, sizes):
    """b minus its mean on each consecutive block of the given sizes."""
    parts = np.split(b, np.cumsum(sizes)[:-1])
    return np.concatenate([p - p.mean() for p in parts])


def test_disconnected_regions_and_a_leaf_that_is_a_component():
    A = sp.csr_matrix(sp.block_diag([make_frame(256, SEED).A, make_frame(256, SEED + 1).A,
                                     path_laplacian(3)]))
    lv = Leaves(np.arange(515), np.array([0, 128, 256, 384, 512, 515]), "natural")
    b = consistent(np.random.default_rng(3).standard_normal(515), [256, 256, 3])
    check_disconnected(A, b, lv, 3)


def test_floating_pieces_that_share_leaves():
    """50 floating 4-cell paths next to a frame: METIS leaves mix whole paths with the frame,
    so A_c's null vectors are sums over several components."""
    A = sp.csr_matrix(sp.block_diag([make_frame(256, SEED).A] + [path_laplacian(4)] * 50))
    b = consistent(np.random.default_rng(4).standard_normal(456), [256] + [4] * 50)
    lv = metis_leaves(A, leaf=64)
    check_disconnected(A, b, lv, 51)


def test_a_null_vector_that_is_not_constant_gets_a_noted_shift():
    """Signless path Laplacian (null vector +1, -1, ...): its leaf block's Cholesky 'succeeds'
    with a rounding-size pivot, which must be caught and shifted, not inverted."""
    w = np.random.default_rng(11).uniform(0.5, 2.0, 63)
    W = sp.diags([w, w], [-1, 1])
    A = sp.csr_matrix(sp.diags(np.asarray(W.sum(1)).ravel()) + W)
    alt = (-1.0) ** np.arange(64)
    pre = setup(A, contiguous_leaves(64, leaf=64), coarse="const")
    M = dense_operator(pre)
    assert pre.leaf_note == "1 leaf block(s) shifted by 1e-12 x row-sum bound"
    assert np.all(np.isfinite(M)) and np.abs(M).max() < 1e14
    b = np.random.default_rng(7).standard_normal(64)
    res = pcg(A, b - (b @ alt) / 64 * alt, pre.apply, 1e-8)
    assert res.converged and res.iterations <= 3


def test_given_basis_depends_on_its_span_only():
    fr = make_frame(1024, SEED)
    lv = choose_leaves(fr.A, fr.coords)
    an = analyse(fr.A, lv)
    basis = np.zeros((lv.n_leaves, lv.max_size, 2))
    basis[:, :, 1] = 3.0                              # the constant, scaled, plus a zero column
    r = np.random.default_rng(4).standard_normal(1024)
    const, given = factor(an, fr.A, coarse="const"), factor(an, fr.A, coarse="given", basis=basis)
    assert given.rank == 3 and given.coarse_size == 3 * lv.n_leaves       # 2 given (zero after the constant) + it
    assert np.allclose(given.apply(r), const.apply(r), rtol=0, atol=1e-10 * np.abs(const.apply(r)).max())


def test_values_only_refactor_equals_a_fresh_setup():
    A1, A2 = make_frame(1024, SEED).A, make_frame(1024, SEED + 5).A
    assert np.array_equal(A1.indices, A2.indices) and not np.allclose(A1.data, A2.data)
    lv = choose_leaves(A1, make_frame(1024, SEED).coords)
    an = analyse(A1, lv)
    old = factor(an, A1)
    refactored, fresh = factor(an, A2), setup(A2, lv)
    r = np.random.default_rng(5).standard_normal(1024)
    assert np.array_equal(refactored.apply(r), fresh.apply(r))
    assert not np.allclose(old.apply(r), fresh.apply(r))
    # the caller's entry order: reversed column order within each row gives the same operator
    rev = sp.csr_matrix(A2, copy=True)
    for i in range(1024):
        lo, hi = rev.indptr[i], rev.indptr[i + 1]
        rev.indices[lo:hi], rev.data[lo:hi] = rev.indices[lo:hi][::-1], rev.data[lo:hi][::-1]
    assert np.allclose(setup(rev, lv).apply(r), fresh.apply(r), rtol=1e-12, atol=0)


def test_linear_to_working_precision():
    fr = make_frame(1024, SEED)
    pre = setup(fr.A, choose_leaves(fr.A, fr.coords), coarse="eig", rank=4)
    rng = np.random.default_rng(6)
    x, y = rng.standard_normal((2, 1024))
    lhs = pre.apply(2.5 * x - 0.75 * y)
    assert np.linalg.norm(lhs - 2.5 * pre.apply(x) + 0.75 * pre.apply(y)) <= 1e-12 * np.linalg.norm(lhs)


def test_describe_times_and_memory():
    fr = make_frame(1024, SEED)
    pre = setup(fr.A, choose_leaves(fr.A, fr.coords), coarse="eig", rank=2)
    text = "\n".join(pre.describe())
    assert "K=8" in text and "r=2" in text and "size 16" in text and "bytes per unknown" in text
    assert set(pre.times) == {"leaf", "coarse_space", "coarse_operator"}
    assert "setup ms: analysis" in text and all(f"{k.replace('_', ' ')} " in text for k in pre.times)
    assert 128 * 8 <= pre.nbytes / pre.n <= 128 * 8 + 200


def test_bad_input_is_named():
    fr = make_frame(256, SEED)
    lv = choose_leaves(fr.A, fr.coords, leaf=64)
    an = analyse(fr.A, lv)
    with pytest.raises(ValueError, match="pattern"):
        factor(an, sp.csr_matrix(fr.A + sp.eye(256, k=7)))
    with pytest.raises(ValueError, match="square"):
        analyse(sp.csr_matrix((256, 255)), lv)
    with pytest.raises(ValueError, match="leaves cover"):
        analyse(make_frame(100, 0).A, lv)
    with pytest.raises(ValueError, match="coarse kind"):
        factor(an, fr.A, coarse="smooth")
    with pytest.raises(ValueError, match="rank"):
        factor(an, fr.A, coarse="eig", rank=0)
    with pytest.raises(ValueError, match="basis"):
        factor(an, fr.A, coarse="given", basis=np.ones((lv.n_leaves, 63, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        factor(an, sp.csr_matrix((fr.A.data * np.nan, fr.A.indices, fr.A.indptr), shape=fr.A.shape))
    with pytest.raises(ValueError, match="shape"):
        factor(an, fr.A).apply(np.ones(255))
