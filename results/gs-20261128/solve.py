"""Single solves of a foreign study case, a fresh Mat and KSP each (the Neumann case with its null space attached),
HTPPC under the options given as name=value (CG to 1e-8 in the unpreconditioned norm, one thread): prints each
run's setup and solve ms, iterations, reason and true relative residual, then the least setup + solve. From the
repository root:  python results/gs-20261128/solve.py CASE N REPS [name=value ...]"""
import sys

import numpy as np
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.onesolve import solve_once  # noqa: E402

case, n, reps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
db = PETSc.Options()
for name, value in [("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                    ("ksp_max_it", "500"), ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")] + \
        [arg.split("=") for arg in sys.argv[4:]]:
    db[name] = value
A, b = CASES[case](n, 0)
A = A.tocsr()
A.sort_indices()
singular = np.abs(A.sum(axis=1)).max() <= 1e-10 * np.abs(A.diagonal()).max()
best = (np.inf, 0)
for run in range(reps):
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    if singular:
        mat.setNullSpace(PETSc.NullSpace().create(constant=True))
    rhs = mat.createVecLeft()
    rhs.array[:] = b - b.mean() if singular else b
    its, reason, setup, solve, relres = solve_once(mat, rhs)
    best = min(best, (setup + solve, its))
    print(f"{case} {n} {' '.join(sys.argv[4:]) or 'as it comes'} run {run}: setup {setup:.1f} solve {solve:.1f} ms, "
          f"{its} iterations, reason {reason}, true relres {relres:.1e}")
    for obj in (mat, rhs):
        obj.destroy()
print(f"{case} {n} {' '.join(sys.argv[4:]) or 'as it comes'}: least setup + solve {best[0]:.1f} ms ({best[1]})")
