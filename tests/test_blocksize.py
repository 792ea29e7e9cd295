"""A block size read off the nonzero pattern (:mod:`petsc_htp.twolevel.blocksize`): elasticity handed over as a bare
AIJ Mat gets the leaves and coarse space of its block size, scalar matrices keep none."""
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from pyamg.gallery import linear_elasticity, poisson

import petsc4py  # noqa: F401  (a missing PETSc fails here, never skips)
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.onesolve import timed_solve  # noqa: E402
from petsc_htp.scenes import meshes  # noqa: E402
from petsc_htp.twolevel.aggregation import aggregates  # noqa: E402
from petsc_htp.twolevel.blocksize import CANDIDATES, detect  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MPIEXEC = shutil.which("mpiexec", path=f"{Path(sys.executable).parent}:{__import__('os').environ.get('PATH', '')}")
assert MPIEXEC, "mpiexec not found (the Makefile installs MPICH)"


def sorted_csr(A):
    A = sp.csr_matrix(A)
    A.sort_indices()
    return A


def found(A, start=0) -> list:
    """The candidate block sizes whose nodes block these rows."""
    return [b for b, count in zip(CANDIDATES, detect(A.indptr, A.indices, start)[0]) if count > 0]


def test_elasticity_patterns_are_blocked_and_scalar_ones_are_not():
    assert found(sorted_csr(linear_elasticity((30, 30))[0])) == [2]
    for b in (4, 6):                                            # nodes of b rows coupled as a 2-D Laplacian's
        assert found(sorted_csr(sp.kron(poisson((20, 20)), np.ones((b, b))) + sp.identity(400 * b)))[0] == b
    assert found(sorted_csr(meshes.q1_elasticity(5)[0])) == [3]
    for A in (poisson((40, 40)), poisson((12, 12, 12)), CASES["dmda2d"](4096, 0)[0], CASES["fem_tri"](4096, 0)[0],
              CASES["fem_hex"](4096, 0)[0]):
        assert found(sorted_csr(A)) == []
    line = sp.diags([1.0, -4.0, 6.0, -4.0, 1.0], [-2, -1, 0, 1, 2], (128, 128))
    wide = sp.kron(line, sp.identity(128)) + sp.kron(sp.identity(128), line)   # reach 2 and 2 nx: whole nodes of 2
    for A in (wide, line, sp.identity(600)):                   # ... also shifted by a row: not a system's nodes
        assert found(sorted_csr(A)) == []


def test_a_rank_may_start_inside_a_node_and_a_block_need_not_store_its_zeros():
    """Rows from global row 1 (the first node's second row) or 2: still nodes of 2. Without its explicit zeros
    (scipy's arithmetic drops them: 28 % of PyAMG's elasticity, 15 % of the trilinear one) each node's rows together
    still couple whole nodes."""
    A = sorted_csr(linear_elasticity((30, 30))[0])
    assert found(sorted_csr(A[1:]), 1) == [2] and found(sorted_csr(A[2:]), 2) == [2]
    for B, b in ((A, 2), (sorted_csr(meshes.q1_elasticity(6)[0]), 3)):
        dropped = B.copy()
        dropped.eliminate_zeros()
        assert dropped.nnz < B.nnz and found(dropped) == [b]


def test_too_few_rows_tell_nothing():
    """A rank with no whole node to check (one row, none, a partial node) answers 0 nodes checked, not a block
    size; the block size then needs MIN_NODES nodes over all ranks."""
    A = sorted_csr(linear_elasticity((30, 30))[0])
    for rows, start in ((A[5:6], 5), (A[:0], 0), (A[1:2], 1)):
        rows = sorted_csr(rows)
        assert all(count in (0, -1) for count in detect(rows.indptr, rows.indices, start)[0])
        assert found(rows, start) == []


def test_the_largest_nodes_whose_blocks_hang_together():
    """Nodes of 2, 4 and 6 all block a block-diagonal matrix of 2 x 2 blocks, but a node of 4 or 6 is then two or
    three uncoupled blocks: 2 is taken. Nodes of 6 coupled inside (a Laplacian of 6 x 6 blocks) take 6."""
    from petsc_htp.collective import Collective
    from petsc_htp.twolevel.blocksize import block_size

    for A, b in ((sp.block_diag([np.array([[2.0, -1.0], [-1.0, 2.0]])] * 600), 2),
                 (sp.kron(poisson((20, 20)), np.ones((6, 6))) + sp.identity(2400), 6)):
        A = sorted_csr(A)
        mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                  A.data))
        assert block_size(mat, A, Collective(mat.getComm())) == (b, "found in the pattern")
        mat.destroy()


def test_aggregates_keep_nodes_whole_across_a_cut_node():
    A = sorted_csr(linear_elasticity((30, 30))[0])[1:, 1:]     # the first node cut: its second row alone
    part = aggregates(sorted_csr(A), bs=2, second="pairs", offset=1)
    assert np.array_equal(part[1::2], part[2::2])               # rows 2k+1, 2k+2 of A[1:] are one node
    assert not np.array_equal(part[0::2][:-1], part[1::2])      # not nodes of 2 from row 0


def solve(A, *options):
    """A fresh CG + HTPPC on the bare AIJ ``A`` with ``options``: (iterations, reason, relres, -ksp_view text)."""
    db = PETSc.Options()
    settings = dict(ksp_type="cg", ksp_norm_type="unpreconditioned", ksp_rtol="1e-8", ksp_max_it="1000",
                    pc_type="python", pc_python_type="petsc_htp.HTPPC", **dict(zip(options[::2], options[1::2])))
    for key, value in settings.items():
        db.setValue(key, value)
    try:
        mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                                  A.data))
        mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        ksp = PETSc.KSP().create()
        ksp.setOperators(mat)
        ksp.setFromOptions()
        rhs, x = mat.createVecLeft(), mat.createVecRight()
        rhs.setArray(np.random.default_rng(0).standard_normal(A.shape[0]))
        its, reason, _, _, relres = timed_solve(ksp, rhs, x)
        return its, reason, relres, "\n".join(ksp.getPC().getPythonContext().setup.describe())
    finally:
        for key in settings:
            db.delValue(key)


@pytest.mark.parametrize("A,bs", [(linear_elasticity((70, 70))[0], 2), (meshes.q1_elasticity(14)[0], 3)],
                         ids=["2-D", "3-D"])
def test_bare_elasticity_takes_the_block_size_of_its_pattern(A, bs):
    """PyAMG's 2-D elasticity (9 800 rows) and 3-D trilinear elasticity (9 450 rows) as bare AIJ Mats: the block
    size found in the pattern cuts CG's iterations several times over (-htp_block_size 1: the scalar leaves)."""
    A = sorted_csr(A)
    its, reason, relres, text = solve(A)
    scalar, *_ = solve(A, "htp_block_size", "1")
    assert reason > 0 and relres <= 1.01e-8
    print(f"block size {bs}: {its} iterations, {scalar} with -htp_block_size 1")
    assert its <= 55 and 2 * its < scalar, (its, scalar)
    assert f"block size {bs}, found in the pattern: each component's constant" in text, text
    _, _, _, forced = solve(A, "htp_block_size", str(bs))
    assert f"block size {bs}, from -htp_block_size" in forced
    with pytest.raises(PETSc.Error) as err:
        solve(A, "htp_block_size", "65")
    assert "-htp_block_size 65 is more unknowns per node than 64" in str(err.value.__cause__ or err.value)


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_block_size_found_on_every_rank(ranks):
    """On 2 and 3 ranks, with PETSc's split and with every rank boundary inside a node, every rank finds block
    size 2 in bare elasticity and none in a scalar Laplacian (tests/blocksize_case.py)."""
    out = subprocess.run([MPIEXEC, "-n", str(ranks), sys.executable, str(ROOT / "tests" / "blocksize_case.py")],
                         cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "blocksize ok" in out.stdout
