"""Operators as PETSc programs hand them over: BAIJ and SBAIJ Mats, a block size, a near null space."""
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from pyamg.gallery import linear_elasticity

import petsc4py  # noqa: F401  (a missing PETSc fails here, never skips)
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: F401,E402

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "elasticity.py"
OPTS = ("-ksp_type", "cg", "-ksp_norm_type", "unpreconditioned", "-ksp_rtol", "1e-8", "-pc_type", "python",
        "-pc_python_type", "petsc_htp.HTPPC")
MPIEXEC = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{__import__('os').environ.get('PATH', '')}")
assert MPIEXEC, "mpiexec not found (the Makefile installs MPICH)"


def run_case(n, *args):
    """examples/elasticity.py with CG + HTPPC under mpiexec: [(its, reason, relres, analyses, numeric)] per solve,
    and the output."""
    out = subprocess.run([MPIEXEC, "-n", str(n), sys.executable, str(EXAMPLE), *OPTS, *map(str, args)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text
    rows = re.findall(r"solve \d: its (\d+) reason (-?\d+) relres (\S+) analyses (\d+) numeric (\d+)", text)
    assert len(rows) == 2, text
    return [(int(i), int(r), float(x), int(a), int(m)) for i, r, x, a, m in rows], text


@pytest.mark.mpi
@pytest.mark.parametrize("ranks,kind", [(1, "sbaij"), (2, "baij"), (2, "sbaij")])
def test_baij_and_sbaij_operators_converge_and_keep_their_analysis(ranks, kind):
    """A BAIJ or SBAIJ (upper triangle only) operator with block size 2 is taken through an AIJ copy: both solves
    converge as the AIJ operator does, and new values of the same pattern reuse the analysis."""
    rows, _ = run_case(ranks, "-mat_kind", kind, "-near", "bs", "-side", 110)
    aij, _ = run_case(ranks, "-mat_kind", "aij", "-near", "bs", "-side", 110)
    for (its, reason, relres, _, _), (its_aij, *_) in zip(rows, aij):
        assert reason > 0 and relres <= 1.01e-8
        assert its == its_aij
    assert [(a, m) for *_, a, m in rows] == [(1, 1), (1, 2)]


@pytest.mark.mpi
def test_block_size_and_near_null_space_shape_the_coarse_space():
    """Elasticity (24k rows): the block size's component constants and then the attached rigid-body modes cut CG's
    iterations several times over, on one and two ranks, and -ksp_view says where the vectors came from. A Mat
    with no block size gets it from its pattern (:mod:`petsc_htp.twolevel.blocksize`); ``-htp_block_size 1``
    treats it as scalar."""
    for ranks in (1, 2):
        scalar, _ = run_case(ranks, "-mat_kind", "aij", "-near", "none", "-side", 110, "-htp_block_size", 1)
        bare, found = run_case(ranks, "-mat_kind", "aij", "-near", "none", "-side", 110, "-ksp_view")
        bs, _ = run_case(ranks, "-mat_kind", "aij", "-near", "bs", "-side", 110)
        rbm, text = run_case(ranks, "-mat_kind", "aij", "-near", "rbm", "-side", 110, "-ksp_view")
        assert rbm[0][0] < bs[0][0] <= 50 < 3 * 50 < scalar[0][0]
        assert bare[0][0] == bs[0][0] and "block size 2, found in the pattern" in found
        assert rbm[0][0] <= 32
    assert "3 per leaf, from 3 near null vector(s) per leaf spanning the piece constants (the Mat's near null space)" \
        in text                             # the translations span each piece's constant: no column of its own
    _, text = run_case(1, "-mat_kind", "aij", "-near", "bs", "-side", 110, "-ksp_view")
    assert ("from 1 near null vector(s) per leaf beside the piece constants (block size 2, the Mat's: each "
            "component's constant)") in text


@pytest.mark.mpi
def test_3d_elasticity_pairs_its_node_aggregates():
    """3-D elasticity (trilinear hexahedra, block size 3, 9 450 rows): with the block size alone the node aggregates
    are paired, as for a scalar 3-D matrix (two standard passes made leaves of 120-735 rows and took 67-79
    iterations); the six rigid-body modes attached keep the standard passes (paired, their seven columns per leaf
    outgrow the coarse LU) and need fewer iterations still, on one and two ranks."""
    for ranks in (1, 2):
        bs, paired = run_case(ranks, "-dim", 3, "-near", "bs", "-side", 14, "-ksp_view")
        rbm, text = run_case(ranks, "-dim", 3, "-near", "rbm", "-side", 14, "-ksp_view")
        assert all(reason > 0 and relres <= 1.01e-8 for _, reason, relres, _, _ in bs + rbm)
        assert rbm[0][0] < bs[0][0] <= 55 and rbm[0][0] <= 40, (bs, rbm)
        assert "second pass pairs" in paired and "second pass standard" in text, text
        assert "6 per leaf, from 6 near null vector(s) per leaf spanning the piece constants" in text, text


@pytest.mark.mpi
def test_a_coarse_v_cycle_gets_the_coarse_near_null_space():
    """Where GAMG solves the 3-D coarse operator of an operator with near null vectors, it is told their coarse
    coefficients W^T z (W holds each z exactly), not only W^T 1: 3-D elasticity with the rigid-body modes on paired
    leaves took 44-54 iterations with W^T 1 alone (9 450 and 20 577 rows) and 102 at 150 000, now 25-26, on one and
    two ranks."""
    for ranks in (1, 2):
        rows, text = run_case(ranks, "-dim", 3, "-near", "rbm", "-side", 14, "-htp_aggregation", "pairs",
                              "-htp_coarse_solver", "gamg", "-ksp_view")
        assert "GAMG" in text and all(r[1] > 0 for r in rows) and rows[0][0] <= 32, rows


def test_near_null_vectors_lie_in_the_coarse_space():
    """W's columns (orthonormal per leaf) hold every attached near null vector exactly."""
    A, B = linear_elasticity((50, 50), format="csr")
    A = sp.csr_matrix(A)
    mat = PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
    mat.setBlockSize(2)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    vecs = [PETSc.Vec().createWithArray(B[:, j].copy(), comm=PETSc.COMM_SELF) for j in range(B.shape[1])]
    mat.setNearNullSpace(PETSc.NullSpace().create(vectors=vecs, comm=PETSc.COMM_SELF))
    pc = PETSc.PC().create(PETSc.COMM_SELF)
    pc.setOperators(mat, mat)
    pc.setType("python")
    pc.setPythonType("petsc_htp.HTPPC")
    PETSc.Options().setValue("htp_direct_max", 0)
    try:
        pc.setFromOptions()
        pc.setUp()
    finally:
        PETSc.Options().delValue("htp_direct_max")
    W = pc.getPythonContext().setup.ops.W
    indptr, indices, values = W.getValuesCSR()
    Wd = sp.csr_matrix((values, indices, indptr), shape=W.getSize()).toarray()
    assert np.allclose(Wd.T @ Wd, np.diag((np.abs(Wd).sum(0) > 0).astype(float)), atol=1e-10)
    assert np.linalg.norm(B - Wd @ (Wd.T @ B)) <= 1e-10 * np.linalg.norm(B)
    pc.destroy()
    mat.destroy()


def test_rigid_body_modes_span_the_constant_and_a_block_size_alone_does_not():
    """nearnull.spans_constant: the rigid-body modes' translations sum to the constant (the piece constants then get
    no column of their own); a block size alone, or vectors that miss the constant, do not."""
    from petsc_htp.twolevel import nearnull

    A, B = linear_elasticity((12, 12), format="csr")
    A = sp.csr_matrix(A)
    for vectors, spans in ((B, True), (B[:, 2:], False), (None, False)):
        mat = PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
        mat.setBlockSize(2)
        if vectors is not None:
            vecs = [PETSc.Vec().createWithArray(vectors[:, j].copy(), comm=PETSc.COMM_SELF)
                    for j in range(vectors.shape[1])]
            mat.setNearNullSpace(PETSc.NullSpace().create(vectors=vecs, comm=PETSc.COMM_SELF))
        assert nearnull.spans_constant(mat) == spans
        mat.destroy()


def test_a_singular_matrix_whose_near_null_space_spans_the_constant_keeps_a_nonsingular_coarse_operator():
    """A Neumann Laplacian (row sums zero) with the constant attached as its near null space, as a GAMG user would:
    the one-piece leaves take no column of their own constant, but each component's first piece keeps one, which the
    null component then drops (without it nothing was left out and E was singular)."""
    m = 30
    one_d = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (m, m)).tolil()
    one_d[0, 0] = one_d[-1, -1] = 1.0
    A = (sp.kron(one_d, sp.identity(m)) + sp.kron(sp.identity(m), one_d)).tocsr()
    mat = PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ones = PETSc.Vec().createWithArray(np.full(m * m, 1.0 / m), comm=PETSc.COMM_SELF)
    mat.setNearNullSpace(PETSc.NullSpace().create(vectors=[ones], comm=PETSc.COMM_SELF))
    db = PETSc.Options("sn_")
    for key, value in (("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                       ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC"), ("htp_direct_max", "0"),
                       ("htp_ordering", "aggregation"), ("htp_aggregation", "standard")):
        db.setValue(key, value)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix("sn_")
    ksp.setOperators(mat)
    ksp.setFromOptions()
    b = PETSc.Vec().createWithArray(np.random.default_rng(0).standard_normal(m * m), comm=PETSc.COMM_SELF)
    b.shift(-b.sum() / (m * m))
    x = b.duplicate()
    ksp.solve(b, x)
    setup = ksp.getPC().getPythonContext().setup
    assert setup.st.covered and setup.space.dropped.size == 1          # the null component's column, left out
    assert ksp.getConvergedReason() > 0 and ksp.getIterationNumber() <= 40
    for obj in (ksp, mat, ones, b, x):
        obj.destroy()


def test_near_null_vectors_keep_the_coarse_lu_and_take_the_const_space():
    """With near null vectors of its own an operator keeps the coarse LU on several ranks (GAMG's V-cycle on the
    coarse operator does not know its near null space) and takes the piece constants besides them."""
    from petsc_htp.twolevel import sizing

    assert sizing.coarse_solver(2, 50_000, 2, "aggregation") == "gamg"
    assert sizing.coarse_solver(2, 50_000, 2, "aggregation", near=2) == "lu"
    past = sizing.COARSE_DIRECT_MAX[2] + 1                                          # past any direct solve
    assert sizing.coarse_solver(2, past, 1, "aggregation", near=2) == "gamg"
    assert sizing.coarse_space(2, 0) == "eig" and sizing.coarse_space(3, 0) == "const"
    assert sizing.coarse_space(2, 3) == "const"


def test_a_baij_operator_whose_pattern_grows_gets_a_new_copy_and_analysis():
    """New nonzeros in the same BAIJ Mat: a new AIJ copy and a new analysis; the earlier copy lives until the
    analysis that held it is freed, and both solves converge."""
    A = sp.csr_matrix(linear_elasticity((30, 30), format="csr")[0])
    n = A.shape[0]
    mat = PETSc.Mat().create(comm=PETSc.COMM_SELF)
    mat.setSizes((n, n), bsize=2)
    mat.setType("baij")
    mat.setUp()
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    for i in range(n):
        mat.setValues([i], A.indices[A.indptr[i]:A.indptr[i + 1]], A.data[A.indptr[i]:A.indptr[i + 1]])
    mat.assemble()
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix("grow_")
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-8, max_it=500)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonType("petsc_htp.HTPPC")
    PETSc.Options().setValue("grow_htp_direct_max", 0)
    try:
        ksp.setFromOptions()
        b, x = mat.createVecs()
        b.setRandom()
        ksp.solve(b, x)
        ctx = ksp.getPC().getPythonContext()
        first = ctx._aij
        assert ksp.getConvergedReason() > 0 and ctx.analysis_count == 1
        far = n - 2                                                 # couple node 0 to the last node: new blocks
        mat.setValues([0, 1], [far, far + 1], -1e-3 * np.eye(2))
        mat.setValues([far, far + 1], [0, 1], -1e-3 * np.eye(2))
        mat.assemble()
        mat.shift(1e-2)
        ksp.solve(b, x)
        assert ksp.getConvergedReason() > 0 and ctx.analysis_count == 2
        assert ctx._aij is not first and ctx._retired == [] and not first.handle    # freed with the old analysis
    finally:
        PETSc.Options().delValue("grow_htp_direct_max")
        ksp.destroy()
        mat.destroy()


@pytest.mark.parametrize("kind", ["seqaij", "mpiaij"])
def test_an_mpiaij_operator_on_one_rank_converges_as_seqaij_does(kind):
    """MATMPIAIJ on one rank (``-mat_type mpiaij``, MatCreateMPIAIJWithArrays on a one-rank COMM_WORLD) is taken
    through a SEQAIJ copy: PETSc has no product of MPIAIJ with the coarse space's SEQAIJ (its PtAP failed with
    'product is not supported'). The two-level method at 22 500 rows converges as it does on SEQAIJ."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (150, 150))
    S = (sp.kron(sp.identity(150), T) + sp.kron(T, sp.identity(150))).tocsr()
    A = PETSc.Mat().create(PETSc.COMM_SELF)
    A.setSizes(S.shape)
    A.setType(kind)
    A.setPreallocationCSR((S.indptr, S.indices))
    A.setValuesCSR(S.indptr, S.indices, S.data)
    A.assemble()
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8, max_it=200)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonContext(petsc_htp.HTPPC())
    b, x = A.createVecLeft(), A.createVecRight()
    b.set(1.0)
    ksp.solve(b, x)
    assert A.getType() == kind and ksp.getConvergedReason() > 0
    assert np.linalg.norm(S @ x.getArray() - 1.0) <= 1.01e-8 * np.sqrt(S.shape[0])
    assert ksp.getIterationNumber() <= 35 and type(ksp.getPC().getPythonContext().setup).__name__ == "TwoLevelPC"


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_an_mpisbaij_matrix_set_from_its_upper_triangle_gets_a_true_aij_copy(ranks):
    """An MPISBAIJ matrix of 3x3 blocks set row by row from its upper triangle (MAT_IGNORE_LOWER_TRIANGULAR, as an
    assembly loop writes it): PETSc's own conversion to MPIAIJ reads its diagonal blocks wrongly (a product off by
    about 25; 3-D elasticity of 46 800 rows on 2 ranks then stopped at 3 000 CG iterations), HTPPC's copy is U + U^T
    - diag(U) of the upper triangle and multiplies as the SBAIJ matrix does."""
    case = Path(__file__).parent / "sbaij_case.py"
    found = {}
    for how in ("raw", "htppc"):
        out = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(case), how], cwd=ROOT,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stdout + out.stderr
        found[how] = float(re.search(r"difference (\S+)", out.stdout).group(1))
    assert found["raw"] > 1.0 and found["htppc"] <= 1e-12, found


def test_a_small_baij_operator_is_factored_as_its_aij_twin_is():
    """A BAIJ Mat of 2x2 blocks (two uncoupled 5-point Laplacians interleaved, 7 200 rows) stores each block's zeros:
    10 entries a row where 5 couple. The small matrix's choice counts the nonzero ones, as for its AIJ twin, and takes
    one Cholesky factor (at most one iteration; counting the stored entries it took ICC(0), 33 iterations)."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (60, 60))
    S = sp.kron(sp.kron(sp.identity(60), T) + sp.kron(T, sp.identity(60)), sp.identity(2)).tocsr()
    S.eliminate_zeros()
    found = {}
    for kind in ("aij", "baij"):
        A = PETSc.Mat().createAIJ(S.shape, csr=(S.indptr, S.indices, S.data), comm=PETSc.COMM_SELF)
        A.setBlockSize(2)
        A = A.convert(kind)
        ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        ksp.setOperators(A)
        ksp.setType("cg")
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(petsc_htp.HTPPC())
        b, x = A.createVecs()
        b.set(1.0)
        ksp.solve(b, x)
        assert ksp.getConvergedReason() > 0
        found[A.getType()] = (ksp.getIterationNumber(), A.getInfo()["nz_used"] / S.shape[0])
        ksp.destroy()
        A.destroy()
    assert found["seqbaij"][1] >= 9.5 and found["seqaij"][1] <= 5.0, found
    assert found["seqbaij"][0] == found["seqaij"][0] <= 1, found
