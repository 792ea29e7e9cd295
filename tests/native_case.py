"""One default HTPPC solve of a bare DMDA-style matrix, run by tests/test_native.py under mpiexec: prints the
iterations, whether PETSc's options database is as it was before the setup, and the inner solvers' prefixes."""
import sys

import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.petscmat import frame_mat, frame_vec  # noqa: E402
from petsc_htp.bench.studies.foreign import bare_frame  # noqa: E402


def main():
    db = PETSc.Options()
    A, b = CASES[db.getString("case", "dmda2d")](db.getInt("n", 16384), 0)
    frame = bare_frame(A, b, "")
    mat = frame_mat(frame, PETSc.COMM_WORLD)
    rhs = frame_vec(frame, mat)
    x = rhs.duplicate()
    ksp = PETSc.KSP().create(PETSc.COMM_WORLD)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8)
    pc = ksp.getPC()
    pc.setType("python")
    pc.setPythonType("petsc_htp.HTPPC")
    ksp.setFromOptions()
    before = db.getAll()
    ksp.solve(rhs, x)
    after = db.getAll()
    ctx = pc.getPythonContext()
    inner = {role: p.getOptionsPrefix() + " " + p.getType() for role, p in ctx.getInnerPCs().items()}
    PETSc.Sys.Print(f"reason {ksp.getConvergedReason()} iterations {ksp.getIterationNumber()}")
    PETSc.Sys.Print(f"options unchanged: {before == after} {sorted(set(after.items()) ^ set(before.items()))}")
    PETSc.Sys.Print(f"inner: {inner}; leaf {ctx.getLeafPC().getOptionsPrefix()}; "
                    f"coarse {ctx.getCoarsePC().getOptionsPrefix()}")
    PETSc.Sys.Print(f"torch loaded: {'torch' in sys.modules}")
    from petsc_htp.threads import thread_pools

    PETSc.Sys.Print(f"BLAS threads: {sorted({getter() for _, getter in thread_pools()})}")
    for obj in (ksp, mat, rhs, x):
        obj.destroy()


if __name__ == "__main__":
    main()
