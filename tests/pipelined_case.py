"""mpiexec -n N python tests/pipelined_case.py SIDE [PETSc options]: PETSc's ksp ex45 system (a 7-point Laplacian on
SIDE^3 nodes whose boundary rows hold just their diagonal while the interior rows keep their couplings to them; the
solution is 1 there and smooth inside) solved by HTPPC under CG and PIPECG; prints a line per KSP type (iterations,
reason, true relres, the form HTPPC's two-level method took, or 'vcycles')."""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1] + sys.argv[2:])
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

comm = PETSc.COMM_WORLD


def ex45(side):
    """ex45's operator (spacing h = 1 / (SIDE - 1): 6 h on the diagonal, -h to each neighbour) as AIJ, rows split as
    PETSc decides, and its right-hand side (6 h on the boundary, h^3 inside)."""
    n = side ** 3
    idx = np.arange(n).reshape((side,) * 3)
    inner = np.zeros((side,) * 3, dtype=bool)
    inner[1:-1, 1:-1, 1:-1] = True
    rows, cols = [np.arange(n)], [np.arange(n)]
    for axis in range(3):
        for shift in (1, -1):
            neighbour = np.roll(idx, shift, axis=axis)
            rows.append(idx[inner])
            cols.append(neighbour[inner])
    h = 1.0 / (side - 1)
    vals = h * np.concatenate([np.full(n, 6.0)] + [np.full(inner.sum(), -1.0)] * 6)
    A = sp.csr_matrix((vals, (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    lo, hi = PETSc.Vec().createMPI(n, comm=comm).getOwnershipRange()
    loc = A[lo:hi]
    M = PETSc.Mat().createAIJ([[hi - lo, n], [hi - lo, n]], comm=comm,
                              csr=(loc.indptr.astype(PETSc.IntType), loc.indices.astype(PETSc.IntType), loc.data))
    M.assemble()
    b = M.createVecLeft()
    b.setArray(np.where(inner.ravel()[lo:hi], h ** 3, 6.0 * h))
    return M, b


def main():
    A, b = ex45(int(sys.argv[1]))
    x = A.createVecRight()
    for kind in ("cg", "pipecg"):
        ksp = PETSc.KSP().create(comm)
        ksp.setOperators(A)
        ksp.setType(kind)
        ksp.setTolerances(rtol=1e-8, max_it=200)
        ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        pc = ksp.getPC()
        pc.setType("python")
        pc.setPythonType("petsc_htp.HTPPC")
        x.set(0.0)
        ksp.solve(b, x)
        r = b.duplicate()
        A.mult(x, r)
        r.aypx(-1.0, b)
        setup = pc.getPythonContext().analysis
        form = setup.forms.form(kind) if hasattr(setup, "forms") else "vcycles"
        PETSc.Sys.Print(f"{kind} its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} "
                        f"relres {r.norm() / b.norm():.3e} form {form}", comm=comm)
        for obj in (ksp, r):
            obj.destroy()


if __name__ == "__main__":
    main()
