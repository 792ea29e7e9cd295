"""Single solves of a foreign study case, a fresh Mat and KSP each (the Neumann case with its null space attached),
HTPPC under the options given as name=value (CG to 1e-8 in the unpreconditioned norm, one thread): prints each
run's setup and solve ms, iterations, reason and true relative residual, then the least setup + solve. From the
repository root:  python results/gs-20261128/solve.py CASE N REPS [name=value ...]"""
import sys
import time

import numpy as np
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402

case, n, reps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
db = PETSc.Options()
for arg in sys.argv[4:]:
    name, value = arg.split("=")
    db[name] = value
A, b = CASES[case](n, 0)
A = A.tocsr()
A.sort_indices()
singular = np.abs(A.sum(axis=1)).max() <= 1e-10 * np.abs(A.diagonal()).max()
b = b - b.mean() if singular else b
best = np.inf
for run in range(reps):
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    if singular:
        mat.setNullSpace(PETSc.NullSpace().create(constant=True))
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    x = rhs.duplicate()
    ksp = PETSc.KSP().create()
    ksp.setOperators(mat)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8, max_it=500)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonContext(petsc_htp.HTPPC())
    ksp.setFromOptions()
    t0 = time.perf_counter()
    ksp.setUp()
    t1 = time.perf_counter()
    ksp.solve(rhs, x)
    t2 = time.perf_counter()
    r = b - A @ x.array
    r = r - r.mean() if singular else r
    if t2 - t0 < best:
        best, its = t2 - t0, ksp.getIterationNumber()
    print(f"{case} {n} {' '.join(sys.argv[4:]) or 'as it comes'} run {run}: setup {1e3 * (t1 - t0):.1f} solve "
          f"{1e3 * (t2 - t1):.1f} ms, {ksp.getIterationNumber()} iterations, reason {ksp.getConvergedReason()}, true "
          f"relres {np.linalg.norm(r) / np.linalg.norm(b):.1e}")
    for obj in (ksp, mat, rhs, x):
        obj.destroy()
print(f"{case} {n} {' '.join(sys.argv[4:]) or 'as it comes'}: least setup + solve {1e3 * best:.1f} ms ({its})")
