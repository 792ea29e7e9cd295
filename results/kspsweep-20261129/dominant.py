"""The 512^2 5-point matrix + SHIFT I (diagonally dominant rows) solved once under the KSP given, HTPPC as it comes
unless PETSC_OPTIONS says otherwise (read at KSPSetFromOptions); prints the KSP, the shift, iterations, PETSc's reason,
setup + solve ms and what HTPPC chose. From the repository root:
    python results/kspsweep-20261129/dominant.py KSP SHIFT"""
import sys
import time

import petsc4py

petsc4py.init(sys.argv[:1])
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from pyamg.gallery import poisson  # noqa: E402

kind, shift = sys.argv[1], float(sys.argv[2])
A = (poisson((512, 512)) + shift * sp.eye(512 * 512)).tocsr()
A.sort_indices()
it = PETSc.IntType
M = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(it), A.indices.astype(it), A.data))
ksp = PETSc.KSP().create()
ksp.setOperators(M, M)
ksp.setType(kind)
ksp.setTolerances(rtol=1e-8)
ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
ksp.getPC().setType("python")
ksp.getPC().setPythonType("petsc_htp.HTPPC")
ksp.setFromOptions()
x, b = M.createVecs()
b.setRandom()
t0 = time.perf_counter()
ksp.solve(b, x)
ms = 1e3 * (time.perf_counter() - t0)
pc = ksp.getPC()
ctx = pc.getPythonContext() if pc.getType() == "python" else None
chose = type(ctx.setup).__name__ + " " + str(getattr(ctx.setup, "kind", "")) if ctx else pc.getType()
print(kind, shift, ksp.getIterationNumber(), ksp.getConvergedReason(), f"{ms:.0f} ms", chose)
