"""Run under ``mpiexec -n 1`` and ``-n 2`` by tests/test_multilevel.py: each rank's own products of a level
(:mod:`petsc_htp.multilevel.galerkin`) against PETSc's. For the DMDA matrix in 2-D and 3-D (Dirichlet rows, a
coefficient jump; rows split by the DMDA) and for a Neumann case whose rows PETSc splits by its default: the
level's W = (I - w D^-1 A) W0 applied to a random vector against A W0 made by MatMatMult, and its next operator
against MatPtAP with W, after the first build and after a refresh with new values; an AIJ made by
:mod:`petsc_htp.aijarrays` from a rank's rows equals the Mat they came from. Prints ``<case> <max relative
difference>`` on rank 0."""
import sys
from pathlib import Path
from types import SimpleNamespace

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
            level.refresh()
        start = A.getOwnershipRange()[0]
        with local_rows(A) as rows:
            omega = JACOBI / gershgorin(rows, start, A.getComm())
        W0 = level.W.duplicate()                                    # W's pattern; the leaf constants put in
        W0.zeroEntries()
        lo, hi = W0.getOwnershipRange()
        ones = level.W0[:hi - lo]
        W0.setValuesCSR(ones.indptr.astype(PETSc.IntType), ones.indices.astype(PETSc.IntType), ones.data)
        W0.assemble()
        AW0 = A.matMult(W0)
        d = A.getDiagonal()
        d.reciprocal()
        AW0.diagonalScale(L=d)
        W = W0.copy()
        W.axpy(-omega, AW0)
        worst += [_diff(level.W, W), _diff(level.below, A.ptap(level.W))]
    return max(worst)


for name, A in (("dmda2d", dmda.operator(dmda.grid(96, 2), 1e3, 0)),
                ("dmda3d", dmda.operator(dmda.grid(20, 3), 1e3, 0)),
                ("neumann", frame_mat(SimpleNamespace(A=CASES["neumann"](4096, 0)[0])))):
    rows = read_csr(A)
    start, stop = A.getOwnershipRange()
    same = aij(A.getComm(), A.getSizes(), *split(rows, start, stop)).equal(A)
    PETSc.Sys.Print(name, f"{_against_petsc(A):.1e}", "equal" if same else "different")
