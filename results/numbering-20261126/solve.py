"""One case of the foreign study at 65 536 rows, in its program's order or permuted at random, solved 4 times by
HTPPC as it comes from the package under the path given (a checkout of some commit); prints the median setup and
solve ms of the last 3 and the iterations.

    OMP_NUM_THREADS=1 python solve.py CHECKOUT CASE natural|random
"""
import os
import sys

sys.path.insert(0, sys.argv[1])
import petsc4py  # noqa: E402

petsc4py.init(["solve"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from timed import fresh_solve  # noqa: E402

assert petsc_htp.__file__.startswith(sys.argv[1]), petsc_htp.__file__
case, order = sys.argv[2], sys.argv[3]
A, b = CASES[case](65536, 0)
if order == "random":
    p = np.random.default_rng(0).permutation(A.shape[0])
    A, b = sp.csr_matrix(A[p][:, p]), b[p]
    A.sort_indices()
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data))
mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
out = []
for _ in range(4):
    setup_ms, solve_ms, its, _ = fresh_solve(mat, b)
    out.append((setup_ms, solve_ms))
setup, solve = np.median(np.array(out[1:]), axis=0)
print(f"{case} {order} {os.path.basename(sys.argv[1].rstrip('/'))} its {its} setup {setup:.1f} solve {solve:.1f} "
      f"total {setup + solve:.1f}")
