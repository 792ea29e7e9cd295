"""The multilevel variant (``-htp_variant multilevel``): its levels, its V-cycle's convergence on foreign matrices
(singular ones too), its options and view, and two ranks."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

from petsc_htp.bench.foreigncases import CASES
from petsc_htp.multilevel import cycle
from petsc_htp.multilevel.hierarchy import Hierarchy
from petsc_htp.multilevel.level import Level
from petsc_htp.petscmat import local_rows
from test_foreign import EXAMPLE, HTPPC_FLAGS, _mpirun, lines, solve

ROOT = Path(__file__).resolve().parent.parent


def _mat(A):
    return PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)


def test_a_level_keeps_its_leaves_apart_and_its_coarse_vectors_sum_to_one():
    """The leaf-block matrix holds exactly the entries within a leaf; the smoothed coarse vectors still sum to one
    on every coupled row where A's row sums vanish (W 1 = 1 - w D^-1 A 1), and decoupled rows get none."""
    A, _ = CASES["neumann"](4096, 0)
    mat = _mat(A)
    level = Level(mat)
    B = level.B.getValuesCSR()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(B[0]))
    assert np.all(level.leaf[rows] == level.leaf[B[1]])
    inside = level.leaf[A.tocoo().row] == level.leaf[A.tocoo().col]
    assert B[1].size == np.count_nonzero(inside)
    ones = level.W.createVecRight()
    ones.set(1.0)
    y = level.W.createVecLeft()
    level.W.mult(ones, y)
    assert np.allclose(y.getArray(), 1.0)
    E = level.below
    assert E.getSize()[0] == level.W.getSize()[1] < A.shape[0] / 3
    D, _ = CASES["dmda2d"](4096, 0)
    dmat = _mat(D)
    dl = Level(dmat)
    W = dl.W.getValuesCSR()
    rows = np.repeat(np.arange(D.shape[0]), np.diff(W[0]))
    held = np.bincount(rows[W[2] != 0], minlength=D.shape[0])
    assert np.count_nonzero(held == 0) == 4 * 63    # the DMDA's boundary rows: no coarse vector
    for m in (level, dl):
        m.destroy()
    for m in (mat, dmat, E, dl.below):
        m.destroy()


def test_coarser_3d_levels_keep_their_leaves_large():
    """A 3-D Laplacian whose z couplings are 0.1 of the others (24^3 rows): at one threshold on every level the
    smoothed coarse operators' many small couplings are all weak and the aggregates shrink (operator complexity
    above 3); a coarser level whose leaves average fewer than 7 rows aggregated again at half the threshold (the
    3-D default) keeps it below 2.6, as HTPPC's V-cycles show in -ksp_view, where CG converges."""
    side = 24
    e = np.ones(side)
    T, eye = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1]), sp.identity(side)
    A = (sp.kron(sp.kron(T, eye), eye) + sp.kron(sp.kron(eye, T), eye) + 0.1 * sp.kron(sp.kron(eye, eye), T)).tocsr()
    mat = _mat(A)
    complexity = {}
    for least in (0.0, 7.0):
        h = Hierarchy(mat, coarse_max=100, least=least)
        complexity[least] = h.complexity()
        h.destroy()
    mat.destroy()
    assert complexity[0.0] > 3.0 and complexity[7.0] < 2.6, complexity
    reason, its, relres, ksp, _ = solve(A, A @ np.ones(A.shape[0]), htp_variant="multilevel", htp_direct_max=0,
                                        htp_ml_coarse_max=100)
    found = re.search(r"operator complexity ([\d.]+)", lines(ksp))
    assert reason > 0 and relres <= 1e-8 and found and float(found[1]) < 2.6, (reason, relres, found)


def test_the_hierarchy_ends_at_the_coarse_size_and_its_options_are_checked():
    A, _ = CASES["fem_tri"](16384, 0)
    mat = _mat(A)
    h = Hierarchy(mat, coarse_max=300)
    rows = h.rows()
    assert rows[0] == A.shape[0] and rows[-1] <= 300 and all(a > 2 * b for a, b in zip(rows, rows[1:]))
    assert 1.0 < h.complexity() < 2.0
    h.destroy()
    h = Hierarchy(mat, coarse_max=300, max_levels=2)
    assert len(h.rows()) == 2
    h.destroy()
    with pytest.raises(PETSc.Error) as err:
        solve(A, np.ones(A.shape[0]), htp_variant="multilevel", htp_ml_damping=2.5)
    assert re.search(r"-fo\d+_htp_ml_damping in \(0, 2\) and -fo\d+_htp_ml_jacobi positive; got 5000, 12, 2.5, 1.4",
                     str(err.value.__cause__))


@pytest.mark.parametrize("case, most", [("dmda2d", 22), ("free_surface", 18), ("fem_tri", 22), ("lognormal", 26),
                                        ("neumann", 20), ("dmda3d", 18), ("fem_tet", 34)])
def test_the_v_cycle_converges_on_foreign_matrices(case, most):
    """CG with the V-cycle reaches 1e-8 on the true residual at about 16 000 rows in at most ``most`` iterations
    (the Neumann case singular, its null space attached; no factor of the whole matrix: ``-htp_direct_max 0``; a
    coarsest operator of at most 1 000 rows, the 3-D default, so that 2-D takes three levels too), and the view shows
    the levels and PCMG."""
    A, b = CASES[case](16384, 0)
    reason, its, relres, ksp, _ = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000)
    assert reason > 0 and its <= most and relres <= 1e-8, (reason, its, relres)
    text = lines(ksp)
    smoother = "one Richardson step" if case == "fem_tet" else "one Gauss-Seidel sweep"   # positive couplings
    assert re.search(r"levels: [3-9], rows \d+ -> \d+", text) and f"smoother: {smoother}" in text, text
    assert ksp.getPC().getPythonContext().getInnerPCs()["multigrid"].getType() == "mg"


def test_tetrahedra_need_the_smoothers_damped():
    """On P1 tetrahedra the leaf blocks overlap in A's energy (lambda(B^-1 A) near 3 on the finest level): undamped
    (-htp_ml_damping near 2 and scale 1) the V-cycle is no longer positive definite; damped, CG converges."""
    A, b = CASES["fem_tet"](16384, 0)
    reason, its, relres, ksp, _ = solve(A, b, htp_variant="multilevel")
    scale = float(re.search(r"scaled (\S+),", lines(ksp)).group(1))
    assert scale < 0.7 and reason > 0
    reason, its, relres, ksp, _ = solve(A, b, htp_variant="multilevel", htp_ml_mg_levels_ksp_richardson_scale=1.0)
    assert reason < 0 or its > 40


@pytest.mark.parametrize("smoother", ["auto", "leaves"])
def test_two_ranks_build_the_levels_each_from_its_own_rows(smoother):
    """On 2 ranks (rows split in the case's own order) the V-cycle converges as on one, the coarse operator's banded
    Cholesky factor on each rank;
    the 2-D graph's smoother is Gauss-Seidel, each rank's sweep forward down and backward up, and ``-htp_ml_smoother
    leaves`` takes PCBJACOBI's blocks as the leaf solve."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", "2", sys.executable, str(ROOT / "examples" / "matrix_file.py"), "-case",
                          "dmda2d", "-n", "40000", "-ksp_type", "cg", "-ksp_norm_type", "unpreconditioned",
                          "-ksp_rtol", "1e-8", "-pc_type", "python", "-pc_python_type", "petsc_htp.HTPPC",
                          "-htp_variant", "multilevel", "-htp_ml_smoother", smoother, "-ksp_view"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "gathered and factored on each of the 2 ranks" in out.stdout and "type: redundant" not in out.stdout
    levels = out.stdout.split("Down solver (pre-smoother) on level 1")[1].split("Up solver")[0]
    if smoother == "leaves":
        leaf = levels.split("type: bjacobi")[1]                              # the blocks' own solver: exact
        assert "type: cholesky" in leaf and "type: ilu" not in leaf, leaf
    else:
        up = out.stdout.split("Up solver (post-smoother) on level 1")[1].split("Down solver")[0]
        assert "type = local_forward" in levels and "type = local_backward" in up, levels + up
        assert "forward down and backward up, unscaled" in out.stdout
    assert int(re.search(r"^iterations: (\d+)$", out.stdout, re.M).group(1)) <= 24, out.stdout
    assert float(re.search(r"true relative residual .*: (\S+)", out.stdout).group(1)) <= 1.2e-8


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_richardson_takes_the_v_cycles_on_a_3d_graph(ranks):
    """Under KSPRICHARDSON a bare 3-D graph above the whole factors' sizes takes the V-cycles (:func:`.choice.fixed_point`:
    the two-level method's leaf solves put eigenvalues of M A above 2, where Richardson diverges), also on 2 ranks whose
    rows lie at random (P1 tets of 12 167 rows, frame 0's values: DIVERGED_DTOL after 664 steps on one rank, none in
    10 000 on two, under ``-htp_variant twolevel``, which keeps that method)."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(ROOT / "examples" / "matrix_file.py"), "-case",
                          "fem_tet", "-n", "12000", "-ksp_type", "richardson", "-ksp_norm_type", "unpreconditioned",
                          "-ksp_rtol", "1e-8", "-pc_type", "python", "-pc_python_type", "petsc_htp.HTPPC",
                          "-ksp_view"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "by the KSP: a fixed-point iteration, KSPRICHARDSON" in out.stdout, out.stdout
    assert re.search(r"^converged reason: 2\b", out.stdout, re.M), out.stdout
    assert float(re.search(r"true relative residual .*: (\S+)", out.stdout).group(1)) <= 1.2e-8


def test_the_leaves_order_changes_no_iteration_and_blocks_take_the_two_level_method():
    """The levels built on the rows in their leaves' order (the default) and on the user's order take the same
    iterations on P1 triangles numbered at random; a Mat with a block size takes the two-level method, and the view
    says why."""
    A, b = CASES["fem_tri"](16384, 0)
    runs = [solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_reorder=flag) for flag in (1, 0)]
    assert all(r[0] > 0 for r in runs) and abs(runs[0][1] - runs[1][1]) <= 1, [r[1] for r in runs]
    assert "in their leaves' order" in lines(runs[0][3]) and "in their leaves' order" not in lines(runs[1][3])
    E, c = CASES["dmda2d"](16384, 0)
    mat = PETSc.Mat().createAIJ(E.shape, bsize=2, csr=(E.indptr, E.indices, E.data), comm=PETSc.COMM_SELF)
    reason, its, relres, ksp, _ = solve(E, c, mat=mat, htp_variant="multilevel", htp_direct_max=0)
    assert reason > 0 and relres <= 1e-8
    ctx = ksp.getPC().getPythonContext()
    assert "block size 2 (the Mat's) takes the two-level method" in ctx.variant.note and "coarse:" in lines(ksp)
    assert ctx.variant.title.startswith("two-level preconditioner")


def test_leaves_in_reverse_cuthill_mckee_order_keep_the_coarse_rows_near_their_neighbours():
    """On P1 triangles numbered at random the leaves renumbered by banded_leaves are the same leaves, and the rows
    taken in their order make a coarse operator whose couplings lie near its diagonal (median |i - j| 39 of 2 153
    rows, against 588 in the leaves' own numbering), so that every level's products and V-cycle read memory in
    order; -htp_variant multilevel takes the rows in that order and hands the levels those numbers."""
    from petsc_htp.multilevel.level import banded_leaves, leaves
    from petsc_htp.petscmat import read_csr

    A, _ = CASES["fem_tri"](16384, 0)
    mat = _mat(A)
    with local_rows(mat) as rows:
        leaf = leaves(mat, rows)
        new = banded_leaves(mat, rows, leaf)
    assert len(set(zip(leaf, new))) == len(np.unique(leaf)) == len(np.unique(new))     # the same leaves
    spans = []
    for label in (leaf, new):
        perm = np.argsort(label, kind="stable").astype(PETSc.IntType)
        order = PETSc.IS().createGeneral(perm, comm=PETSc.COMM_SELF)
        P = mat.createSubMatrix(order, order)
        level = Level(P, leaf=label[perm], blocks=False)
        C = read_csr(level.below)
        spans.append(np.median(np.abs(C.indices - np.repeat(np.arange(C.shape[0]), np.diff(C.indptr)))))
        level.below.destroy()
        level.destroy()
        for obj in (P, order):
            obj.destroy()
    assert spans[1] < spans[0] / 5, spans
    reason, its, relres, ksp, _ = solve(A, np.ones(A.shape[0]), mat=mat, htp_variant="multilevel", htp_direct_max=0)
    setup = ksp.getPC().getPythonContext().setup
    C = read_csr(setup.hierarchy.levels[0].below)
    span = np.median(np.abs(C.indices - np.repeat(np.arange(C.shape[0]), np.diff(C.indptr))))
    assert setup.P is not None and np.all(np.diff(setup.hierarchy.levels[0].leaf) >= 0) and span == spans[1], span
    ksp.destroy()
    mat.destroy()


def test_the_reordered_copy_takes_new_values_by_its_map():
    """Rows numbered at random: on one rank the V-cycles' reordered copy is made from the operator's rows by a map of
    its entries (:mod:`petsc_htp.multilevel.reordered`), and new values of the pattern reach it by that map: the copy
    is MatCreateSubMatrix's of the operator's values, entry for entry, at the first solve and after new values that
    keep the leaves and that make them anew (RENEW), and CG converges on each."""
    A, b = CASES["fem_tri"](16384, 0)
    mat = _mat(A)
    ksp, ages = None, []
    for frame in (0, 1, 2, 3):               # kept leaves, or (more iterations than RENEW allows) new ones
        B, _ = CASES["fem_tri"](16384, frame)
        if frame:
            mat.setValuesCSR(B.indptr, B.indices, B.data)
            mat.assemble()
        opts = {} if frame else {"htp_variant": "multilevel", "htp_direct_max": 0}
        reason, its, relres, ksp, _ = solve(B, b, mat=mat, ksp=ksp, **opts)
        setup = ksp.getPC().getPythonContext().setup
        assert reason > 0 and relres <= 1e-8, (reason, relres)
        assert setup.reordered.take is not None and setup.P.handle == setup.reordered.P.handle
        ages.append(setup.age)
        fresh = mat.createSubMatrix(setup.order, setup.order)
        assert fresh.equal(setup.P)
        fresh.destroy()
    assert max(ages) > 0 and 0 in ages[1:], ages           # kept leaves and new ones both refilled
    ksp.destroy()
    mat.destroy()


def test_reordered_matches_matcreatesubmatrix_entry_for_entry():
    """multilevel.reordered on one rank: the copy of a matrix with stored zeros (the entries two columns off the
    diagonal) and a row of its diagonal alone is MatCreateSubMatrix's, bit for bit, with the symmetry flag kept;
    refilled with new values it is again, its state raised, so that PCSOR's sweep is a fresh copy's."""
    from petsc_htp.multilevel.reordered import Reordered

    A = sp.random(300, 300, density=0.03, random_state=3, format="csr")
    A = (A + A.T + sp.eye(300) * 10).tolil()
    A[5, 7], A[7, 5] = 1.0, 1.0
    A[9, :], A[:, 9] = 0.0, 0.0
    A[9, 9] = 2.0
    A = A.tocsr()
    A.sort_indices()
    A.data[np.flatnonzero((np.repeat(np.arange(300), np.diff(A.indptr)) - A.indices) ** 2 == 4)] = 0.0   # stored zeros
    assert A.nnz > np.count_nonzero(A.data) and A.indptr[10] - A.indptr[9] == 1 and (A != A.T).nnz == 0
    mat = _mat(A)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    perm = np.random.default_rng(1).permutation(300)
    order = PETSc.IS().createGeneral(perm.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    with local_rows(mat) as rows:
        made = Reordered(mat, rows, perm, order)
    fresh = mat.createSubMatrix(order, order)
    assert made.P.equal(fresh) and made.P.isSymmetricKnown() == (True, True)
    x, y, z = fresh.createVecs()[0], fresh.createVecs()[0], fresh.createVecs()[0]
    x.setRandom()
    made.P.SOR(x, y)                                            # PCSOR's diagonal cached for the old values
    mat.scale(3.0)
    state = made.P.stateGet()
    with local_rows(mat) as rows:
        made.refill(rows)
    mat.createSubMatrix(order, order, submat=fresh)
    assert made.P.equal(fresh) and made.P.stateGet() > state
    y.set(0.0)
    z.set(0.0)
    made.P.SOR(x, y)
    fresh.SOR(x, z)
    assert np.array_equal(y.getArray(), z.getArray())
    for obj in (made.P, fresh, order, mat, x, y, z):
        obj.destroy()


def test_a_large_bare_graph_takes_the_v_cycles_as_it_comes(tmp_path):
    """HTPPC as it comes takes the V-cycles for a bare 2-D graph of at least MIN_ROWS rows in a local order, and
    says so, and keeps them for new values on the same KSP; ``-htp_variant twolevel`` keeps the two-level
    method; numbered at random it takes them too on one rank, its rows in their leaves' order; so does a 3-D DMDA
    matrix, with Gauss-Seidel, while P1 tetrahedra (a third of their couplings positive) and fewer rows keep the
    two-level method (multilevel.choice)."""
    from petsc_htp.multilevel import choice
    from petsc_htp.scenes import foreign
    from petsc_htp.twolevel.graphshape import graph_shape

    side = int(np.ceil(np.sqrt(choice.MIN_ROWS)))
    A, b = foreign.dmda(2, side, 1e3, 0)
    reason, its, relres, ksp, _ = solve(A, b)
    note = ksp.getPC().getPythonContext().variant.note
    assert reason > 0 and relres <= 1e-8 and its <= 24 and "multilevel V-cycles in place" in note
    assert "levels:" in lines(ksp)
    viewer = PETSc.Viewer().createASCII(str(tmp_path / "view.txt"))
    ksp.view(viewer)
    viewer.destroy()
    assert "HTPPC, variant twolevel: multilevel preconditioner" in (tmp_path / "view.txt").read_text()
    mat = ksp.getOperators()[0]
    mat.setValuesCSR(A.indptr, A.indices, 2.0 * A.data)       # a simulation's next frame: the V-cycles kept
    mat.assemble()
    reason, its2, relres, ksp, _ = solve(2.0 * A, b, mat=mat, ksp=ksp)
    assert reason > 0 and relres <= 1e-8 and abs(its2 - its) <= 1 and "kept from 1 numeric setup" in lines(ksp)
    reason, its, relres, ksp, _ = solve(A, b, htp_variant="twolevel")
    assert reason > 0 and "form:" in lines(ksp) and not ksp.getPC().getPythonContext().variant.note
    mat = _mat(A)
    with local_rows(mat) as rows:
        shape = graph_shape(rows, want_weak=False, samples=8)
        assert choice.serves(mat, rows, lambda: shape)[0] and choice.local_order(rows, 0)
        rng = np.random.default_rng(0)
        p = rng.permutation(A.shape[0])
        shuffled = A[p][:, p].tocsr()
        assert not choice.local_order(shuffled, 0)
    m = _mat(shuffled)
    with local_rows(m) as rows:
        why, reorder, dim = choice.serves(m, rows, lambda: graph_shape(rows, want_weak=False, samples=8))
        assert reorder and dim == 2 and "numbered at random" in why, why
    m.destroy()
    cube, b = foreign.dmda(3, int(np.ceil(choice.MIN_ROWS ** (1 / 3))), 1e3, 0)
    reason, its, relres, ksp, _ = solve(cube, b)
    assert reason > 0 and relres <= 1e-8 and its <= 18, (reason, its, relres)
    note, text = ksp.getPC().getPythonContext().variant.note, lines(ksp)
    assert "bare 3-D graph" in note and "positive" in note and "smoother: one Gauss-Seidel sweep" in text, note
    small, _ = foreign.dmda(2, side - 20, 1e3, 0)
    tets, _ = CASES["fem_tet"](choice.MIN_ROWS + 4000, 0)
    for other, dim in ((small, 0), (tets, 3)):
        m = _mat(other)
        with local_rows(m) as rows:
            assert other.shape[0] >= choice.MIN_ROWS or dim == 0
            assert choice.serves(m, rows, lambda: graph_shape(rows, want_weak=False, samples=8)) == ("", False, dim)
            assert choice.signed(m, rows) == (dim == 3)
        m.destroy()
    mat.destroy()


def test_new_values_keep_the_leaves_until_keeping_them_costs_more():
    """New values of the pattern that keep the couplings' strengths (the matrix times 2, then rows and columns
    scaled by 1 % at random) keep the finest level's leaves, with its smoothed coarse vectors and Galerkin operator
    of the new values (the coarser levels made anew), and a fresh KSP's iterations on those values; inclusions that moved after solves that
    cost the old leaves no extra iteration are tried on them, where CG takes a few more iterations (the coarser levels, made anew from
    the finest level's new Galerkin operator, follow the new values); a solve that took more than RENEW times
    the first one's makes the next numeric step build the hierarchy anew (here on the moved values: no more
    iterations), as does a move whose cost is known to exceed a new hierarchy's, or one after a single solve (no
    cost measured: unlike the two-level method's, old leaves are not tried); the pattern's analysis stays."""
    from petsc_htp.multilevel import setup
    from petsc_htp.scenes import foreign

    A, b = foreign.dmda(2, 128, 1e3, 0)                 # three levels: the coarsest at most 1 000 rows
    reason, its, relres, ksp, mat = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000)
    ctx = ksp.getPC().getPythonContext()
    assert reason > 0 and ctx.analysis_count == 1
    rng = np.random.default_rng(1)
    d = 1.0 + 0.01 * rng.random(A.shape[0])
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))

    def frame(values):
        mat.setValuesCSR(A.indptr, A.indices, values)
        mat.assemble()
        out = solve(A, b, mat=mat, ksp=ksp)         # (the relres below is checked against the frame's own A)
        return out[1], lines(ksp)

    for age, factor in ((1, 2.0), (2, 2.0 * d[rows] * d[A.indices])):
        its2, text = frame(A.data * factor)
        fresh = solve(sp.csr_matrix((A.data * factor, A.indices, A.indptr), shape=A.shape), b,
                      htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000)
        fresh[3].destroy()
        fresh[4].destroy()
        assert abs(its2 - fresh[1]) <= 1 and f"kept from {age} numeric setup" in text and ctx.analysis_count == 1
    moved, _ = foreign.dmda(2, 128, 1e3, 1)
    ctx.setup.leaf_its, ctx.setup.refresh_ms = [its, its], 0.0     # as measured: no extra iteration, a refresh free
    its3, text = frame(moved.data)                                 # (this machine's timings decide nothing here)
    assert its3 <= its + 4 and "kept from 3 numeric setups" in text and ctx.analysis_count == 1
    ctx.setup.its = int(setup.RENEW * ctx.setup.first_its) + 1             # as if that solve had taken that many
    ctx.setup.leaf_its, ctx.setup.refresh_ms = [its, its], 0.0
    its4, text = frame(moved.data)
    assert its4 <= its3 and "kept from" not in text and ctx.analysis_count == 1      # built anew
    assert "leaves made anew for these values: a solve took" in text
    ctx.setup.leaf_its, ctx.setup.ms_per_it = [its4, its4 + 1000], 1e3      # as if old leaves had cost 1 000 s
    again, _ = foreign.dmda(2, 128, 1e3, 2)
    numeric = ctx.numeric_count
    its6, text = frame(again.data)
    assert ctx.analysis_count == 1 and ctx.numeric_count == numeric + 1 and "kept from" not in text
    assert "leaves made anew for these values: the couplings moved away" in text
    assert its6 <= its + 2
    ksp.destroy()
    mat.destroy()
    reason, its, relres, ksp, mat = solve(A, b, htp_variant="multilevel", htp_direct_max=0)
    ctx = ksp.getPC().getPythonContext()
    its5, text = frame(moved.data)
    assert ctx.analysis_count == 1 and "kept from" not in text and its5 <= its + 2


def test_help_lists_the_multilevel_options_with_their_defaults():
    """-help's multilevel lines (pcoptions.MULTILEVEL_HELP) carry the defaults the code uses."""
    from petsc_htp.multilevel import cycle, hierarchy, level
    from petsc_htp.pcoptions import MULTILEVEL_HELP, HTPOptions

    defaults = {name: default for name, _, default, _ in MULTILEVEL_HELP}
    assert defaults == {"coarse_max": hierarchy.COARSE_MAX[2], "max_levels": hierarchy.MAX_LEVELS,
                        "jacobi": level.JACOBI, "damping": cycle.DAMPING, "smoother": "auto", "reorder": "auto"}
    assert "-htp_ml_damping <real> <default 1.5>" in HTPOptions().help_text("-htp_")


def test_the_coarsest_size_follows_the_graph_dimension():
    """-htp_ml_coarse_max's default: 5 000 rows on a 2-D graph, 1 000 on a 3-D one (whose coarse LU costs more), as
    the view says."""
    for case, most in (("dmda2d", 5000), ("dmda3d", 1000)):
        A, b = CASES[case](16384, 0)
        reason, its, relres, ksp, _ = solve(A, b, htp_variant="multilevel", htp_direct_max=0)
        text = lines(ksp)
        assert reason > 0 and relres <= 1e-8 and f"at most {most} rows" in text, text


def test_the_coarsest_operator_takes_its_band_unless_too_wide_indefinite_or_set_by_the_user():
    """The coarse solve: the banded Cholesky factor of the coarsest operator where its band is narrow enough; the
    sparse LU where it would hold more than COARSE_BAND values (a 160^2 grid: 25 600 rows, 160 wide), where a pivot
    is negative, or where the user set the coarse PC (a coarse KSP option alone keeps the band); either solve is
    exact, so the iterations agree."""
    import scipy.sparse as sp

    from petsc_htp.multilevel.cycle import COARSE_BAND, banded

    A, b = CASES["dmda2d"](16384, 0)
    ours = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000)
    theirs = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000,
                   htp_ml_mg_coarse_pc_type="lu")
    assert "the coarsest by banded Cholesky" in lines(ours[3]) and "the coarsest by lu" in lines(theirs[3])
    kept = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000,
                 htp_ml_mg_coarse_ksp_type="preonly")                # a coarse KSP option alone keeps the band
    assert "the coarsest by banded Cholesky" in lines(kept[3]) and kept[1] == ours[1]
    assert ours[0] > 0 and theirs[0] > 0 and abs(ours[1] - theirs[1]) <= 1, (ours[:3], theirs[:3])
    side = 160
    grid = sp.kron(sp.identity(side), sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], (side, side))) + sp.diags(
        [-1.0, -1.0], [-side, side], (side * side, side * side))
    assert side * side * (side + 1) > COARSE_BAND and banded(_mat(sp.csr_matrix(grid))) is None
    chain = sp.csr_matrix(sp.diags([-1.0, 1.0, -1.0], [-1, 0, 1], (50, 50)))             # symmetric, indefinite
    assert banded(_mat(chain)) is None
    band, grounded = banded(_mat(sp.csr_matrix(sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], (50, 50)))))
    assert band.width == 1 and grounded.size == 0


def test_a_pattern_that_changed_on_one_rank_only_takes_one_method_on_both():
    """2 ranks, the V-cycles chosen as it comes, then new values that change the nonzero mask on rank 0 only: both
    ranks make the V-cycles anew together (the choice had split: a hang) and CG converges; then the matrix times 2
    on both: the finest leaves kept and the coarser levels made anew on both ranks, with the same iterations; each
    rank's rows in their leaves' order (``-htp_ml_reorder 1``), the copy is made again by MatCreateSubMatrix."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", "2", sys.executable, str(ROOT / "tests" / "multilevel_case.py")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert re.search(r"^first MultilevelPC \d+$", out.stdout, re.M), out.stdout
    second = re.search(r"^second (\w+) (\d+) (\S+)$", out.stdout, re.M)
    assert second and second.group(1) == "MultilevelPC" and float(second.group(3)) <= 1.01e-8, out.stdout
    third = re.search(r"^third (\w+) (\d+) (\S+) (\d+)$", out.stdout, re.M)      # values alone: a refresh on 2 ranks
    assert third and third.group(4) == "1" and float(third.group(3)) <= 1.01e-8, out.stdout
    assert abs(int(third.group(2)) - int(second.group(2))) <= 1, out.stdout
    reordered = re.search(r"^reordered (\d+) (\S+) (\d+) (\w+)$", out.stdout, re.M)   # the copy made again on 2 ranks
    assert reordered and float(reordered.group(2)) <= 1.01e-8 and reordered.group(3) == "1", out.stdout
    assert reordered.group(4) == "True", out.stdout


def test_new_values_of_a_singular_matrix_keep_the_smoothers_scale():
    """A Neumann matrix (null space attached) refilled with a new frame's values on the same KSP: MatSetValues
    unsets its symmetric flag, so KSPSolve no longer projects the Lanczos estimate's random b onto A's range; the
    estimate projects it itself, so the new frame's scales and iterations are a fresh solve's (the finest scale had
    been 0.16 against 0.71: 32 against 16 iterations). A levels' option of the user's (here PCMG's default smoother
    restated) has the finest level estimated by Lanczos too."""
    A, b = CASES["neumann"](16384, 0)                   # three levels: the coarsest at most 1 000 rows
    reason, its, relres, ksp, mat = solve(A, b, htp_variant="multilevel", htp_ml_coarse_max=1000,
                                          htp_ml_mg_levels_pc_type="jacobi")
    A1, b1 = CASES["neumann"](16384, 1)
    mat.setValuesCSR(A1.indptr, A1.indices, A1.data)
    mat.assemble()
    assert not mat.isSymmetricKnown()[0]
    reason, its1, relres, ksp, _ = solve(A1, b1, mat=mat, ksp=ksp)
    fresh = solve(A1, b1, htp_variant="multilevel", htp_ml_coarse_max=1000, htp_ml_mg_levels_pc_type="jacobi")
    scale = [float(re.search(r"scaled (\S+),", lines(k)).group(1)) for k in (ksp, fresh[3])]
    assert reason > 0 and relres <= 1e-8 and its1 <= fresh[1] + 1 and abs(scale[0] - scale[1]) < 0.05, (its1, scale)
    assert scale[0] != 0.75, scale                      # Lanczos', not 1.5 over the Gershgorin bound 2


@pytest.mark.parametrize("case, bounded", [("dmda2d", True), ("neumann", True), ("aniso_e0.01_a30", False)])
def test_the_finest_jacobi_scale_takes_the_gershgorin_bound_of_weakly_dominant_rows(case, bounded, monkeypatch):
    """Where the finest level's rows are weakly diagonally dominant (the Gershgorin bound of D^-1 A is 2, which a
    mesh's checkerboard mode nearly reaches; at most DOMINANT) its Jacobi smoother is scaled by that bound, 1.5 / 2,
    with no Lanczos run on it (1M-row DMDA: the V-cycle's set-up 66-76 against 196-211 ms, the same iterations), as
    the view says; rotated anisotropy's 9-point rows are not dominant (bound 2.42): Lanczos, as on every level where
    the user set a levels' option. Either way CG converges as before."""
    runs = []

    def counted(smoother):
        runs.append(smoother.getOperators()[0].getSize()[0])
        return largest(smoother)

    largest = cycle._largest
    monkeypatch.setattr(cycle, "_largest", counted)
    A, b = CASES[case](16384, 0)
    reason, its, relres, ksp, mat = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000,
                                          htp_ml_smoother="jacobi")
    setup = ksp.getPC().getPythonContext().setup
    finest, levels = A.shape[0], len(setup.hierarchy.levels)
    assert (setup.hierarchy.levels[0].bound <= cycle.DOMINANT) == bounded and levels >= 2
    assert (finest not in runs) == bounded and len(runs) == levels - bounded, runs
    text = lines(ksp)
    assert ("the finest level's Gershgorin bound, Lanczos' on the others" in text) == bounded, text
    assert (float(re.search(r"scaled (\S+),", text).group(1)) == 0.75) == bounded
    runs.clear()
    lanczos = solve(A, b, htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=1000,
                    htp_ml_smoother="jacobi", htp_ml_mg_levels_pc_type="jacobi")
    assert runs[0] == finest and len(runs) == levels and "taken to 1.5: Lanczos')" in lines(lanczos[3])
    assert reason > 0 and relres <= 1e-8 and its <= lanczos[1] + 1, (its, lanczos[1])
    for obj in (ksp, mat, lanczos[3], lanczos[4]):
        obj.destroy()


@pytest.mark.parametrize("ranks", [1, 2])
def test_each_ranks_own_products_match_petscs(ranks):
    """A level's coarse space and next operator, made from each rank's rows by scipy's products, equal PETSc's
    MatMatMult and MatPtAP (to rounding) on 1 and 2 ranks, built and refreshed, a rank without rows or without
    couplings to another's included; an AIJ made on a rank's arrays equals the Mat they came from
    (tests/galerkin_case.py)."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(ROOT / "tests" / "galerkin_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert sorted(lines) == ["decoupled_blocks", "dmda2d", "dmda3d", "neumann", "one_rank_owns_all", "uneven"], out.stdout
    for case, text in lines.items():
        diff, same = text.split()
        assert float(diff) < 1e-12 and same == "equal", (case, text)


def test_the_hierarchy_finds_the_coarse_rows_of_null_components_and_spares_the_search_where_there_are_none():
    """The DMDA matrix (Dirichlet rows grounding its one coupled component): every component of the coarsest operator
    holds a coarse row lifted from a grounded one, so no component of A is looked for; beside a floating Neumann
    square (a null component, nothing attached) one coarsest component holds none: its last row is grounded in the
    coarsest factor (at contrast 1e6 rounding hid its null pivot, and CG stopped with DIVERGED_INDEFINITE_MAT), the
    components of A are found, the floating one null, and the V-cycle's input and output are taken off its constant
    (the square alone, and the pair at 20 000 rows, had also stopped so); a null pair of rows, which shrinks to a coarse row coupled to
    nothing, leaves the hierarchy unable to tell (not complete), and the components of A find it."""
    import scipy.sparse as sp

    from petsc_htp.collective import Collective
    from petsc_htp.multilevel.ranges import floating
    from petsc_htp.scenes import foreign

    opts = dict(htp_variant="multilevel", htp_direct_max=0, htp_ml_coarse_max=100)
    D, bd = foreign.dmda(2, 64, 1e3, 0)
    reason, its, relres, ksp, mat = solve(D, bd, **opts)
    setup = ksp.getPC().getPythonContext().setup
    assert reason > 0 and len(setup.hierarchy.levels) >= 2 and setup.range is None and setup.ranges.components is None
    ksp.destroy()
    mat.destroy()
    pair = sp.csr_matrix(np.array([[1.0, -1.0], [-1.0, 1.0]]))

    for seed, side in ((0, 64), (1, 64), (2, 100)):
        N, L = foreign.neumann(side, 1e6, seed)[0], foreign.lognormal(side, 1e6, seed)[0]
        for A in (sp.block_diag([N, L]).tocsr(), N.tocsr()):
            A.sort_indices()
            b = np.random.default_rng(seed).standard_normal(A.shape[0])
            b[:N.shape[0]] -= b[:N.shape[0]].mean()                     # in the range
            reason, its, relres, ksp, mat = solve(A, b, mat=_mat(A), **opts)            # nothing attached
            null = ksp.getPC().getPythonContext().setup.range
            assert reason > 0 and relres <= 1e-7 and null.k == 1, (reason, its, relres)
            ksp.destroy()
            mat.destroy()
    for A, expected in ((D, 0), (sp.block_diag([D, N]).tocsr(), 1), (sp.block_diag([D, pair]).tocsr(), None)):
        A.sort_indices()
        mat = _mat(A)
        rowsum = np.asarray(A.sum(axis=1)).ravel()
        hierarchy = Hierarchy(mat, coarse_max=100)
        rows, complete = floating(hierarchy, np.abs(rowsum) > 1e-10 * A.diagonal().max(), Collective(mat.getComm()))
        assert len(hierarchy.levels) >= 2 and complete == (expected is not None) and rows.size == (expected or 0)
        hierarchy.destroy()
        mat.destroy()
    A = sp.block_diag([D, pair]).tocsr()
    A.sort_indices()
    reason, its, relres, ksp, mat = solve(A, np.concatenate([bd, [1.0, -1.0]]), mat=_mat(A), **opts)
    assert reason > 0 and relres <= 1e-7 and ksp.getPC().getPythonContext().setup.range.k == 1, (reason, relres)
    ksp.destroy()
    mat.destroy()


@pytest.mark.parametrize("smoother", ["gs", "jacobi", "leaves"])
def test_the_v_cycle_runs_on_the_operator_without_its_null_space(smoother):
    """The smoothers' KSPs do not project their right-hand sides on the user's null space (a copy, a sum and a shift
    each, a third of PCMG's time on a Neumann square): its remove function runs only for the outer KSP's own
    projections, about twice an iteration, and the null space is attached again after every application, a
    transpose null space of the user's own too."""
    A, b = CASES["neumann"](16384, 0)
    calls = []
    null = PETSc.NullSpace().create(constant=True, comm=PETSc.COMM_SELF)
    null.setFunction(lambda space, vec: calls.append(1))
    mat = _mat(A)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    mat.setNullSpace(null)
    reason, its, relres, ksp, _ = solve(A, b, mat=mat, htp_variant="multilevel", htp_ml_coarse_max=1000,
                                        htp_ml_smoother=smoother)
    assert reason > 0 and relres <= 1e-8 and its <= 20, (reason, its, relres)
    assert mat.getNullSpace().handle == null.handle
    assert len(calls) <= 2 * its + 4, (len(calls), its)
    own = PETSc.NullSpace().create(constant=True, comm=PETSc.COMM_SELF)
    mat.setTransposeNullSpace(own)
    with cycle.bare(mat):
        assert not mat.getNullSpace().handle
    assert mat.getNullSpace().handle == null.handle and mat.getTransposeNullSpace().handle == own.handle


def test_gauss_seidel_sweeps_both_ways_under_a_levels_option_of_the_users():
    """A levels' option of the user's (here the Richardson step restated) leaves the up smoother under the down one's
    prefix: Gauss-Seidel then sweeps forward and backward each time (PCSOR's own default), so that the V-cycle stays
    symmetric and CG converges as with the sweeps split, and the view says so."""
    A, b = CASES["dmda2d"](16384, 0)
    split = solve(A, b, htp_variant="multilevel", htp_ml_coarse_max=1000)
    both = solve(A, b, htp_variant="multilevel", htp_ml_coarse_max=1000, htp_ml_mg_levels_ksp_type="richardson")
    assert "forward down and backward up" in lines(split[3]) and "both ways (the user's options)" in lines(both[3])
    assert both[0] > 0 and both[2] <= 1e-8 and both[1] <= split[1] + 2, (both[:3], split[:3])
    for obj in (split[3], split[4], both[3], both[4]):
        obj.destroy()


def test_a_null_space_other_than_the_constant_keeps_the_two_level_method():
    """unscalar refuses a null space of vectors other than the constant (the coarse vectors are constants) and takes
    PETSc's constant flag or a user's vector of ones as the constant."""
    from petsc_htp.multilevel import choice

    A = CASES["neumann"](4096, 0)[0]
    mat = _mat(A)
    with local_rows(mat) as rows:
        assert choice.unscalar(mat, rows) == ""
        for values, refused in ((1.0, False), (np.linspace(1.0, 2.0, A.shape[0]), True)):
            vec = mat.createVecRight()
            vec.array[:] = values
            vec.normalize()
            mat.setNullSpace(PETSc.NullSpace().create(vectors=[vec], comm=PETSc.COMM_SELF))
            assert bool(choice.unscalar(mat, rows)) == refused
        mat.setNullSpace(PETSc.NullSpace().create(constant=True, comm=PETSc.COMM_SELF))
        assert choice.unscalar(mat, rows) == ""
    mat.destroy()


def test_the_range_projection_takes_each_null_components_mean_and_the_whole_ones_alone():
    """RangeCheck.project removes each null component's mean from its rows and leaves grounded components alone: one
    component of every row (the mean alone, :attr:`whole`), and two Neumann squares beside a Dirichlet one."""
    from petsc_htp.collective import Collective
    from petsc_htp.twolevel.consistency import RangeCheck

    square = CASES["neumann"](1024, 0)[0].tocsr()
    grounded = (square + sp.eye(square.shape[0])).tocsr()
    n = square.shape[0]
    rng = np.random.default_rng(0)
    for A, comp, null in ((square, np.zeros(n, dtype=np.int64), np.array([True])),
                          (sp.block_diag([square, grounded, square], format="csr"), np.repeat(np.arange(3), n),
                           np.array([True, False, True]))):
        check = RangeCheck(A, comp, null, Collective(PETSc.COMM_SELF))
        vec = PETSc.Vec().createWithArray(rng.standard_normal(A.shape[0]), comm=PETSc.COMM_SELF)
        want = vec.getArray().copy()
        for c in np.flatnonzero(null):
            want[comp == c] -= want[comp == c].mean()
        check.project(vec)
        assert check.whole == (null.size == 1) and np.allclose(vec.getArray(), want, atol=1e-12)


@pytest.mark.parametrize("ranks", [1, 2])
def test_sealed_pockets_leave_no_null_pivot_to_the_smoothers_or_the_coarsest_factor(ranks):
    """A closed domain holding 49 sealed pockets (null components of 9 rows each, handed over bare) converges under
    every smoother on 1 and 2 ranks: the pockets' coarse rows, which rounding leaves at 1e-16 of their scale, are made
    unit rows (on 2 ranks CG had stopped with DIVERGED_INDEFINITE_PC; tests/pockets_case.py)."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", str(ranks), sys.executable, str(ROOT / "tests" / "pockets_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = [line.split() for line in out.stdout.splitlines()]
    assert [line[0] for line in lines] == ["gs", "jacobi", "leaves"], out.stdout
    for smoother, reason, its, relres in lines:
        assert int(reason) > 0 and int(its) <= 20 and float(relres) < 1e-7, (smoother, reason, its, relres)


def test_a_galerkin_row_within_rounding_of_its_scale_becomes_a_unit_row():
    """Rows whose entries all lie within NULL_SHARE of their own scale (or none) are emptied, their columns' entries in
    the rank's other rows dropped, and given their scale (1 where it is 0) on the diagonal; the other rows are kept as
    they were."""
    from petsc_htp.multilevel.galerkin import NULL_SHARE, _unit_null_rows

    C = sp.csr_matrix(np.array([[4.0, -1.0, 1e-17, 0.0], [-1.0, 4.0, 0.0, 0.0], [1e-17, 0.0, -3e-16, 0.0],
                                [0.0, 0.0, 0.0, 0.0]]))
    scale = np.array([4.0, 4.0, 2.0, 1.0])
    out = _unit_null_rows(C, 0, scale).toarray()
    assert np.array_equal(out, np.array([[4.0, -1.0, 0, 0], [-1.0, 4.0, 0, 0], [0, 0, 2.0, 0], [0, 0, 0, 1.0]]))
    assert _unit_null_rows(C, 0, np.array([4.0, 4.0, 2.0, 0.0])).toarray()[3, 3] == 1.0     # no scale: 1
    assert _unit_null_rows(C, 0, scale * 1e-6).toarray()[2, 2] == -3e-16     # against a scale that small: kept
    kept = _unit_null_rows(C[:2], 0, np.array([4.0, 4.0]))              # no null row: the same matrix back
    assert (kept != C[:2]).nnz == 0
    shifted = _unit_null_rows(sp.csr_matrix(C.toarray()[2:3]), 2, np.array([2.0]))   # a rank's rows from 2 on
    assert shifted.toarray().tolist() == [[0.0, 0.0, 2.0, 0.0]] and NULL_SHARE < 1e-12


@pytest.mark.parametrize("variant", ["multilevel", "twolevel"])
def test_a_matrix_scaled_to_1e200_or_1e_200_is_aggregated_without_overflow(variant):
    """The strength tests take square roots of the diagonal before products: a 2-D DMDA matrix times 1e200 (whose
    a_ii a_jj overflowed, with RuntimeWarnings) or 1e-200 (where it underflowed to 0 and every coupling counted as
    strong) converges as the matrix itself does, warnings raised as errors."""
    import warnings

    A, b = CASES["dmda2d"](4096, 0)
    opts = {"htp_variant": variant, "htp_direct_max": 0, **({"htp_ml_coarse_max": 500} if variant == "multilevel" else {})}
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        base = solve(A, b, **opts)[1]
        for scale in (1e200, 1e-200):
            reason, its, relres, ksp, mat = solve(A * scale, b, **opts)
            assert reason > 0 and abs(its - base) <= 2 and relres < 1e-7, (scale, its, base)


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_hierarchy_of_one_level_factors_the_matrix(ranks):
    """V-cycles forced on a matrix no larger than the coarsest size: PCMG's one level is its coarse solve, which takes
    the banded factor or the LU, also where the user set a levels' option for the smoothers (it had taken the
    smoother's one sweep under mg_levels_0_: CG did not converge on a 64^2 DMDA)."""
    lu = "lu" if ranks == 1 else "redundant"
    for n, coarse, how, theirs in (("64", "5000", "banded Cholesky", ()), ("200", "100000", lu, ()),
                                   ("64", "5000", "banded Cholesky", ("-htp_ml_mg_levels_pc_type", "jacobi")),
                                   ("200", "100000", lu, ("-htp_ml_mg_levels_pc_type", "jacobi"))):
        proc = _mpirun(ranks, EXAMPLE, "-n", n, "-htp_variant", "multilevel", "-htp_direct_max", "0",
                       "-htp_ml_coarse_max", coarse, *theirs, *HTPPC_FLAGS)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "iterations: 1\n" in proc.stdout and f"levels: 1, rows {int(n) ** 2} (the coarsest by {how}" in \
            proc.stdout, proc.stdout


def test_rows_strongly_coupled_to_another_rank_are_leaves_of_their_own_on_every_level():
    """Log-normal edge weights exp(5 N(0, 1)) on 2 ranks (tests/edges_case.py, V-cycles forced): a row whose couplings
    to the other rank outweigh the rest is a leaf of its own (ranksplit.cut_rows, as the two-level method's leaves),
    so its coarse column keeps the pair's common mode: 50 CG iterations against 102 (one rank: 43)."""
    mpiexec = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:/usr/bin")
    out = subprocess.run([mpiexec, "-n", "2", sys.executable, str(ROOT / "tests" / "edges_case.py")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    reason, its, relres = out.stdout.split()
    assert int(reason) > 0 and int(its) <= 70 and float(relres) < 1e-7, out.stdout
