"""Run under ``mpiexec -n 1`` and ``-n 2`` by tests/test_multilevel.py: each rank's own products of a level
(:mod:`petsc_htp.multilevel.galerkin`) against PETSc's. For the DMDA matrix in 2-D and 3-D (Dirichlet rows, a
coefficient jump; rows split by the DMDA), for a Neumann case whose rows PETSc splits by its default and for a 2-D
Laplacian split unevenly (rank 0 1 000 rows), held by rank 0 alone, and one decoupled copy of it a rank: the
level's W = (I - w D^-1 A) W0 applied to a random vector against A W0 made by MatMatMult, and its next operator
against MatPtAP with W, after the first build and after a refresh with new values; an AIJ made by
:mod:`petsc_htp.aijarrays` from a rank's rows equals the Mat they came from. Prints ``<case> <max relative
difference>`` on rank 0."""
import sys
from pathlib import Path
from types import SimpleNamespace

import scipy.sparse as sp

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.aijarrays import aij, split  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.multilevel.level import JACOBI, Level, gershgorin  # noqa: E402
from petsc_htp.petscmat import frame_mat, local_rows, read_csr  # noqa: E402
from petsc_htp.scenes import dmda  # noqa: E402


def _diff(P, Q):
    """Relative difference of P x and Q x for a random x."""
    x, y = P.createVecs()
    x.setRandom()
    z = y.duplicate()
    P.mult(x, y)
    Q.mult(x, z)
    z.axpy(-1.0, y)
    return z.norm() / y.norm()


def _against_petsc(A):
    """The largest difference of the level's W and next operator from PETSc's products, built and refreshed."""
    level = Level(A)
    worst = []
    for frame in range(2):
        if frame:
            A.scale(2.0)
            A.shift(0.5)
            level.below.destroy()
            level.refresh()
        start = A.getOwnershipRange()[0]
        with local_rows(A) as rows:
            omega = JACOBI / gershgorin(rows, rows.diagonal(k=start), A.getComm())
        lo, hi = level.W.getOwnershipRangeColumn()
        W0 = aij(A.getComm(), level.W.getSizes(), *split(level.W0[:A.getLocalSize()[0]], lo, hi))
        W = A.matMult(W0)                                           # W0 - omega D^-1 A W0
        d = A.getDiagonal()
        d.reciprocal()
        W.diagonalScale(L=d)
        W.scale(-omega)
        W.axpy(1.0, W0, structure=PETSc.Mat.Structure.SUBSET)
        ptap = A.ptap(level.W)
        worst += [_diff(level.W, W), _diff(level.below, ptap)]
        for obj in (W0, W, d, ptap):
            obj.destroy()
    level.below.destroy()
    level.destroy()
    return max(worst)


def _split(A, first):
    """The scipy CSR ``A`` as a PETSc AIJ whose rank 0 holds its first ``first`` rows and the last rank the rest (a
    rank between them none)."""
    comm = PETSc.COMM_WORLD
    rank, size = comm.getRank(), comm.getSize()
    lo, hi = (0, first) if rank == 0 else (first, A.shape[0]) if rank == size - 1 else (first, first)
    if size == 1:
        lo, hi = 0, A.shape[0]
    rows = A[lo:hi].tocsr()
    mat = PETSc.Mat().createAIJ(((hi - lo, A.shape[0]), (hi - lo, A.shape[0])), comm=comm,
                                csr=(rows.indptr.astype(PETSc.IntType), rows.indices.astype(PETSc.IntType), rows.data))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat


size = PETSc.COMM_WORLD.getSize()
laplacian = CASES["dmda2d"](4096, 0)[0]
blocks = sp.block_diag([laplacian] * size, format="csr")         # one decoupled block a rank
for name, A in (("dmda2d", dmda.operator(dmda.grid(96, 2), 1e3, 0)),
                ("dmda3d", dmda.operator(dmda.grid(20, 3), 1e3, 0)),
                ("neumann", frame_mat(SimpleNamespace(A=CASES["neumann"](4096, 0)[0]))),
                ("uneven", _split(laplacian, 1000)),
                ("one_rank_owns_all", _split(laplacian, laplacian.shape[0])),
                ("decoupled_blocks", _split(blocks, laplacian.shape[0]))):
    rows = read_csr(A)
    start, stop = A.getOwnershipRange()
    made = aij(A.getComm(), A.getSizes(), *split(rows, start, stop))
    same = made.equal(A)
    PETSc.Sys.Print(name, f"{_against_petsc(A):.1e}", "equal" if same else "different")
    made.destroy()
