"""One solve of a foreign study case (frame 1: new values, as a sequence's) or a PyAMG example under the KSP given,
HTPPC as it comes unless PETSC_OPTIONS says otherwise (it is read at KSPSetFromOptions); prints case, KSP,
iterations, PETSc's reason and the true relative residual. From the repository root:
    python results/kspsweep-20261129/one.py CASE KSP [N]"""
import sys

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES, pyamg_cases  # noqa: E402

name, kind = sys.argv[1], sys.argv[2]
A, b = pyamg_cases()[name] if name.startswith("pyamg") else CASES[name](int(sys.argv[3]), 1)
A = A.tocsr()
A.sort_indices()
it = PETSc.IntType
M = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(it), A.indices.astype(it), A.data))
M.setOption(PETSc.Mat.Option.SYMMETRIC, True)
ksp = PETSc.KSP().create()
ksp.setOperators(M, M)
ksp.setType(kind)
ksp.setTolerances(rtol=1e-8, max_it=3000)
ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
ksp.getPC().setType("python")
ksp.getPC().setPythonType("petsc_htp.HTPPC")
ksp.setFromOptions()
x, rhs = M.createVecs()
rhs.array[:] = b
ksp.setUp()
ksp.solve(rhs, x)
r = rhs.duplicate()
M.mult(x, r)
r.aypx(-1, rhs)
print(name, A.shape[0], kind, ksp.getIterationNumber(), ksp.getConvergedReason(), f"{r.norm() / rhs.norm():.2e}")
