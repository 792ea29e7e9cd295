"""One fresh KSP with HTPPC as it comes on ``mat`` (CG to rtol 1e-8 on the true residual, x0 = 0), for the scripts
of this folder: (setup ms, solve ms, iterations, the leaf solver's stored values)."""
import time

import petsc4py

petsc4py.init(["timed"])
from petsc4py import PETSc  # noqa: E402


def fresh_solve(mat, b):
    """Set up and solve ``mat x = b`` (``b`` a numpy array) with a new KSP, destroyed after."""
    import petsc_htp

    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-8)
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    pc = ksp.getPC()
    pc.setType("python")
    ctx = petsc_htp.HTPPC()
    pc.setPythonContext(ctx)
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    x = rhs.duplicate()
    t = time.perf_counter()
    ksp.setUp()
    t1 = time.perf_counter()
    ksp.solve(rhs, x)
    out = (1e3 * (t1 - t), 1e3 * (time.perf_counter() - t1), ksp.getIterationNumber(),
           getattr(ctx.setup, "leafsolver", None) and ctx.setup.leafsolver.nnz())
    ksp.destroy()
    return out
