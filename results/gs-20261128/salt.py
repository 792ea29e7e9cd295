"""A random field of strong edges: each edge of a SIDE^2 5-point grid (Dirichlet around, eliminated) has conductivity
CONTRAST with probability SHARE, else 1; CG to 1e-8 with HTPPC's two-level method and its V-cycles (-htp_variant,
one thread), pyamg's smoothed aggregation (its CG) and AMGCL (its CG): the iterations each takes. From the
repository root:  python results/gs-20261128/salt.py SIDE SHARE CONTRAST"""
import sys

import numpy as np
import petsc4py
import scipy.sparse as sp

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

from petsc_htp.onesolve import solve_once  # noqa: E402

side, share, contrast = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
rng = np.random.default_rng(2)
kx = np.where(rng.random((side + 1, side)) < share, contrast, 1.0)      # kx[i, j]: between nodes (i - 1, j), (i, j)
ky = np.where(rng.random((side, side + 1)) < share, contrast, 1.0)
node = np.arange(side * side).reshape(side, side).T
shape = (side * side,) * 2
x_edges = sp.coo_matrix((-kx[1:-1].ravel(), (node[:-1].ravel(), node[1:].ravel())), shape=shape)
y_edges = sp.coo_matrix((-ky[:, 1:-1].ravel(), (node[:, :-1].ravel(), node[:, 1:].ravel())), shape=shape)
A = (x_edges + x_edges.T + y_edges + y_edges.T + sp.diags((kx[:-1] + kx[1:] + ky[:, :-1] + ky[:, 1:]).T.ravel()))
A = A.tocsr()
A.sort_indices()
b = np.random.default_rng(3).standard_normal(side * side)
out = []
db = PETSc.Options()
for name, value in (("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                    ("ksp_max_it", "2000"), ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")):
    db[name] = value
for variant in ("twolevel", "multilevel"):
    db["htp_variant"] = variant
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data))
    rhs = mat.createVecLeft()
    rhs.array[:] = b
    out.append(f"HTPPC {variant} {solve_once(mat, rhs)[0]}")
    mat.destroy()
    rhs.destroy()
del PETSc.Options()["htp_variant"]
import pyamg  # noqa: E402

residuals = []
pyamg.smoothed_aggregation_solver(A).solve(b, tol=1e-8, accel="cg", residuals=residuals, maxiter=2000)
out.append(f"pyamg SA {len(residuals) - 1}")
try:
    import pyamgcl

    solver = pyamgcl.solver(pyamgcl.amg(A, {}), prm={"type": "cg", "tol": 1e-8, "maxiter": 2000})
    solver(b)
    out.append(f"AMGCL {solver.iters}")
except ImportError:
    out.append("AMGCL not installed")
print(f"side {side}, share {share}, contrast {contrast:g}: iterations " + ", ".join(out))
