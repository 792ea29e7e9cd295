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
from petsc4py import PETSc  # noqa: E402  (the options name petsc_htp.HTPPC: PCPYTHON imports it from this checkout)
from petsc_htp import petscmat  # noqa: E402

comm, side = PETSc.COMM_WORLD, 48
N = side * side


def operator(columns, scale=1.0, flagged=False, diag=4.0):
    """(A, b, x_true): Dirichlet boundary rows by MatZeroRows (``columns`` False) or MatZeroRowsColumns; ``flagged``:
    MAT_SYMMETRIC set before (PETSc keeps it through MatZeroRows)."""
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
    A.setOption(PETSc.Mat.Option.SYMMETRIC, flagged)
    x_true = A.createVecRight()
    x_true.array[:] = np.sin(0.37 * np.arange(lo, hi)) + 1.0
    b = A.createVecLeft()
    A.mult(x_true, b)
    boundary = [r for r in range(lo, hi) if r // side in (0, side - 1) or r % side in (0, side - 1)]
    rows = np.array(boundary, dtype=PETSc.IntType)
    (A.zeroRowsColumns if columns else A.zeroRows)(rows, diag=diag, x=x_true, b=b)
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
for kind in ("cg", "gmres", "bicg", "preonly", "cgs"):
    for label, options in (("direct", {}), ("twolevel", {"htp_direct_max": 0})):
        if kind == "preonly" and label == "twolevel":
            continue
        if kind == "cgs":          # right preconditioning mishandles a start: not started, M = (I - M'E) M'
            options = {**options, "ksp_pc_side": "right"}
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
# a preconditioner reused on new values, new diagonal entries on the Dirichlet rows: the start reads them now
A, b, x_true = operator(False)
ksp = solve(A, b, x_true, "cg", {"htp_direct_max": 0}, "reuse")
ksp.getPC().setReusePreconditioner(True)
C, e, z_true = operator(False, scale=2.0, diag=0.5)
C.copy(A, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
x = A.createVecRight()
ksp.solve(e, x)
x.axpy(-1.0, z_true)
PETSc.Sys.Print(f"reused its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} error "
                f"{x.norm() / z_true.norm():.3e}")
# a solve that raised mid-way (a monitor) skips postSolve: PCApply on a vector that does not vanish on those rows
# still applies the whole M (the factor's: A^-1)
A, b, x_true = operator(False)
ksp = solve(A, b, x_true, "cg", {}, "aborted")


def monitor(ksp, its, rnorm):
    if its == 1:
        raise RuntimeError("stopped by the user's monitor")


ksp.setMonitor(monitor)
try:
    ksp.solve(b, A.createVecRight())
except PETSc.Error:
    pass
y, z = A.createVecs()
ksp.getPC().apply(b, y)
A.mult(y, z)
z.axpy(-1.0, b)
PETSc.Sys.Print(f"after abort {z.norm() / b.norm():.3e}")
# a new operator refused (not symmetric elsewhere) leaves the previous preconditioner whole
ksp.monitorCancel()
R = A.duplicate(copy=True)
lo, hi = R.getOwnershipRange()
if lo <= 5 * side + 5 < hi:
    R.setValue(5 * side + 5, 5 * side + 6, -7.0, addv=PETSc.InsertMode.ADD_VALUES)
R.assemble()
ksp.setOperators(R)
try:
    ksp.solve(b, A.createVecRight())
    PETSc.Sys.Print("refused no")
except PETSc.Error:
    ctx = ksp.getPC().getPythonContext()
    ctx.apply(ksp.getPC(), b, y)
    A.mult(y, z)
    z.axpy(-1.0, b)
    PETSc.Sys.Print(f"refused yes, previous M {z.norm() / b.norm():.3e}")
# an Amat other than the Pmat whose Dirichlet rows hold just the Pmat's diagonal (a copy; MatZeroRowsColumns'; the
# MatZeroRows form beside the MatZeroRowsColumns one as Pmat, also a BAIJ one, whose rows HTPPC reads in its AIJ copy):
# started
SB = S.convert("baij")
for amat, pmat, rhs, name in ((A.duplicate(copy=True), A, b, "amatcopy"), (S, A, c, "amatsym"), (A, S, b, "pmatsym"),
                              (A, SB, b, "pmatbaij")):
    prefix = f"{name}_"
    for key, value in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 300,
                       "pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_direct_max": 0}.items():
        PETSc.Options(prefix).setValue(key, value)
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(amat, pmat)
    ksp.setFromOptions()
    sol = amat.createVecRight()
    ksp.setUp()
    made = petscmat._converted                  # AIJ copies made in the solve itself: none (the set-up's is read)
    copies = []
    petscmat._converted = lambda mat: copies.append(mat.getType()) or made(mat)
    try:
        ksp.solve(rhs, sol)
    finally:
        petscmat._converted = made
    sol.axpy(-1.0, x_true)
    PETSc.Sys.Print(f"pmat {name} its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} error "
                    f"{sol.norm() / x_true.norm():.3e} copies {len(copies)}")
    ksp.destroy()
    sol.destroy()
# an Amat whose product raises (a shell): the probe's failure leaves no work vector of HTPPC's locked


class Failing:
    def mult(self, mat, x, y):
        raise RuntimeError("a transient failure")


shell = PETSc.Mat().createPython(A.getSizes(), Failing(), comm=comm)
shell.setUp()
ksp = solve(A, b, x_true, "cg", {"htp_direct_max": 0}, "shell")
ksp.setOperators(shell, A)
try:
    ksp.solve(b, A.createVecRight())
except PETSc.Error:
    ksp.setOperators(A, A)
    ksp.solve(b, A.createVecRight())
    ksp.getPC().apply(b, y)
    A.mult(y, z)
    z.axpy(-1.0, b)
    PETSc.Sys.Print(f"after a failing Amat its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} "
                    f"PCApply {z.norm() / b.norm():.3e}")
# MAT_SYMMETRIC set before MatZeroRows, which keeps it: probed all the same
F, f, f_true = operator(False, flagged=True)
solve(F, f, f_true, "cg", {"htp_direct_max": 0}, "flagged")
# patterns in turn leave nothing to PETSc's garbage on several ranks (objects dropped without a destroy land there)
import gc  # noqa: E402

ksp = solve(A, b, x_true, "cg", {"htp_direct_max": 0}, "turns")
gc.collect()
PETSc.garbage_cleanup(comm)                 # this program's own dropped objects
sol = A.createVecRight()
for M, rhs in ((S, c), (A, b), (S, c), (A, b)):
    ksp.setOperators(M)
    ksp.solve(rhs, sol)
ksp.destroy()
sol.destroy()
gc.collect()
PETSc.garbage_view(comm)
