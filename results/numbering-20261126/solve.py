"""One case of the foreign study at 65 536 rows, in its program's order or permuted at random, solved 4 times by
HTPPC as it comes from the package under the path given (a checkout of some commit); prints the median setup and
solve ms of the last 3 and the iterations.

    OMP_NUM_THREADS=1 python solve.py CHECKOUT CASE natural|random
"""
import os, sys, time
sys.path.insert(0, sys.argv[1])
import petsc4py; petsc4py.init(['x'])
from petsc4py import PETSc
import numpy as np, scipy.sparse as sp
from petsc_htp.bench.foreigncases import CASES
import petsc_htp
assert petsc_htp.__file__.startswith(sys.argv[1]), petsc_htp.__file__
case, order = sys.argv[2], sys.argv[3]
A, b = CASES[case](65536, 0)
if order == 'random':
    p = np.random.default_rng(0).permutation(A.shape[0]); A = sp.csr_matrix(A[p][:, p]); A.sort_indices(); b = b[p]
M = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data)); M.setOption(PETSc.Mat.Option.SYMMETRIC, True)
out = []
for r in range(4):
    ksp = PETSc.KSP().create(); ksp.setOperators(M); ksp.setType('cg'); ksp.setTolerances(rtol=1e-8); ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    pc = ksp.getPC(); pc.setType('python'); pc.setPythonContext(petsc_htp.HTPPC())
    bb = M.createVecLeft(); bb.array[:] = b; x = bb.duplicate()
    t = time.perf_counter(); ksp.setUp(); t1 = time.perf_counter(); ksp.solve(bb, x); t2 = time.perf_counter()
    out.append(((t1 - t) * 1e3, (t2 - t1) * 1e3)); its = ksp.getIterationNumber()
    ksp.destroy()
o = np.median(np.array(out[1:]), axis=0)
print(f"{case} {order} {os.path.basename(sys.argv[1].rstrip('/'))} its {its} setup {o[0]:.1f} solve {o[1]:.1f} total {o.sum():.1f}")
