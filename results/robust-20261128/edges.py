"""A grid of SIDE^2 cells whose edges have log-normal weights exp(SIGMA N(0, 1)), Dirichlet walls (1 added to the
boundary cells' diagonal): a nonsingular M-matrix whose couplings span many orders, handed over bare to CG (rtol 1e-8,
unpreconditioned norm, at most 500 iterations) with HTPPC as it comes, or the PETSc options given after SIGMA.
Prints the reason, the iterations and the true relative residual. From the repository root:
  python results/robust-20261128/edges.py SIDE SIGMA [name=value ...]"""
import sys

import numpy as np
import scipy.sparse as sp
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

side, sigma = int(sys.argv[1]), float(sys.argv[2])
rng = np.random.default_rng(0)
cell = np.arange(side * side).reshape(side, side)
a = np.concatenate([cell[:, :-1].ravel(), cell[:-1, :].ravel()])
c = np.concatenate([cell[:, 1:].ravel(), cell[1:, :].ravel()])
w = np.exp(sigma * rng.standard_normal(a.size))
wall = np.isin(np.arange(side), (0, side - 1))
A = sp.csr_matrix((np.concatenate([-w, -w, w, w]), (np.concatenate([a, c, a, c]), np.concatenate([c, a, a, c]))),
                  shape=(side * side,) * 2) + sp.diags((wall[:, None] | wall[None, :]).ravel().astype(float))
A = sp.csr_matrix(A)
A.sort_indices()
b = rng.standard_normal(side * side)
db = PETSc.Options()
given = dict(arg.split("=") for arg in sys.argv[3:])
HTP = {} if "pc_type" in given else {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
for name, value in {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": "1e-8", "ksp_max_it": "500",
                    **HTP, **given}.items():
    db[name] = value
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data))
x, rhs = mat.createVecs()
rhs.setArray(b)
ksp = PETSc.KSP().create()
ksp.setOperators(mat)
ksp.setFromOptions()
ksp.solve(rhs, x)
relres = np.linalg.norm(b - A @ x.getArray()) / np.linalg.norm(b)
print(f"{side}^2 sigma {sigma:g} {' '.join(sys.argv[3:]) or 'HTPPC'}: reason {ksp.getConvergedReason()}, "
      f"{ksp.getIterationNumber()} iterations, true relres {relres:.1e}")
