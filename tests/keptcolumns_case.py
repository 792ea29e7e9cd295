"""mpiexec -n N python tests/keptcolumns_case.py: a 2-D 5-point operator with coefficient jumps whose boundary rows
are Dirichlet rows made by PETSc's MatZeroRows (their columns kept: not symmetric), beside the same made by
MatZeroRowsColumns; prints a line per solve (KSP type, options, iterations, true relres, error) and checks
of M itself."""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402,F401  (the options name petsc_htp.HTPPC; imported from this checkout)

comm, side = PETSc.COMM_WORLD, 48
N = side * side


def operator(columns, scale=1.0):
    """(A, b, x_true): Dirichlet boundary rows by MatZeroRows (``columns`` False) or MatZeroRowsColumns."""
    A = PETSc.Mat().createAIJ([N, N], nnz=(5, 4), comm=comm)
    lo, hi = A.getOwnershipRange()
    def cell(i, j):
        return scale * (100.0 if (i // 12 + j // 12) % 2 else 1.0)

    for row in range(lo, hi):
        i, j = divmod(row, side)
        total = 0.0
        for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            if 0 <= i + di < side and 0 <= j + dj < side:
                k = 0.5 * (cell(i, j) + cell(i + di, j + dj))
                A.setValue(row, (i + di) * side + j + dj, -k)
                total += k
        A.setValue(row, row, total + 1e-3)
    A.assemble()
    A.setOption(PETSc.Mat.Option.SYMMETRIC, False)
    x_true = A.createVecRight()
    x_true.array[:] = np.sin(0.37 * np.arange(lo, hi)) + 1.0
    b = A.createVecLeft()
    A.mult(x_true, b)
    boundary = [r for r in range(lo, hi) if r // side in (0, side - 1) or r % side in (0, side - 1)]
    rows = np.array(boundary, dtype=PETSc.IntType)
    (A.zeroRowsColumns if columns else A.zeroRows)(rows, diag=4.0, x=x_true, b=b)
    return A, b, x_true


def solve(A, b, x_true, ksp_type, options, name):
    """One KSPSolve with HTPPC; prints its line."""
    prefix = f"{name}_"
    db = PETSc.Options(prefix)
    krylov = {} if ksp_type == "preonly" else {"ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 300}
    for key, value in {"ksp_type": ksp_type, **krylov, "pc_type": "python", "pc_python_type": "petsc_htp.HTPPC",
                       **options}.items():
        db.setValue(key, value)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    x = A.createVecRight()
    ksp.solve(b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    x.axpy(-1.0, x_true)
    PETSc.Sys.Print(f"solve {name} {ksp_type} its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} "
                    f"relres {r.norm() / b.norm():.3e} error {x.norm() / x_true.norm():.3e}")
    return ksp


A, b, x_true = operator(False)
S, c, _ = operator(True)
for kind in ("cg", "gmres", "bicg", "preonly"):
    for label, options in (("direct", {}), ("twolevel", {"htp_direct_max": 0})):
        if kind == "preonly" and label == "twolevel":
            continue
        for mat, rhs, which in ((A, b, "rows"), (S, c, "rowscols")):
            ksp = solve(mat, rhs, x_true, kind, options, f"{which}_{label}_{kind}")
ksp = solve(A, b, x_true, "cg", {"htp_direct_max": 0}, "view")
ksp.view()
pc = ksp.getPC()                   # the two-level M outside a KSPSolve: (I - M' E) M', and its transpose
u, v, Mu, Mv = A.createVecs() + A.createVecs()
u.setRandom()
v.setRandom()
pc.apply(u, Mu)
pc.applyTranspose(v, Mv)
PETSc.Sys.Print(f"adjoint {abs(v.dot(Mu) - u.dot(Mv)) / abs(v.dot(Mu)):.3e}")
# M itself, applied outside a KSPSolve: the factor of A' makes M = A^-1 and M^T = A^-T
pc = solve(A, b, x_true, "cg", {}, "apply").getPC()
y, z = A.createVecs()
pc.apply(b, y)
A.mult(y, z)
z.axpy(-1.0, b)
w, v = A.createVecs()
pc.applyTranspose(b, w)
A.multTranspose(w, v)
v.axpy(-1.0, b)
PETSc.Sys.Print(f"apply {z.norm() / b.norm():.3e} transpose {v.norm() / b.norm():.3e}")
# new values on the same pattern: the copy follows them, the analysis stays
ksp = solve(A, b, x_true, "cg", {"htp_direct_max": 0}, "again")
B, d, y_true = operator(False, scale=3.0)
B.copy(A, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
x = A.createVecRight()
ksp.solve(d, x)
x.axpy(-1.0, y_true)
ctx = ksp.getPC().getPythonContext()
PETSc.Sys.Print(f"again its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} error "
                f"{x.norm() / y_true.norm():.3e} analyses {ctx.analysis_count} numeric {ctx.numeric_count}")
