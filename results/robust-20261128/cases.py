"""Single solves of matrices that had defeated HTPPC's V-cycles (CG to 1e-8 in the unpreconditioned norm, one thread),
HTPPC as it comes (the V-cycles at these sizes): prints the iterations, PETSc's reason and the true relative
residual. From the repository root (PYTHONPATH selects the tree):
  python results/robust-20261128/cases.py CASE [name=value ...]
CASE: pockets16 / pockets100 (a 256^2 closed domain, Dirichlet walls, holding 16 / 100 sealed 3x3 pockets, each a
null component of its own with a right-hand side of zero mean there, handed over bare), scaled1e200 / scaled1e-200
(the foreign study's dmda2d at 40 000 rows times 1e200 / 1e-200) or dmda2d (times 1)."""
import sys

import numpy as np
import scipy.sparse as sp
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.onesolve import solve_once  # noqa: E402


def pockets(m, every):
    """The closed domain of m^2 cells with 3x3 pockets every ``every`` cells, and its right-hand side."""
    rng = np.random.default_rng(1)
    cell, pocket = np.arange(m * m).reshape(m, m), np.full((m, m), -1)
    for k, (i, j) in enumerate((i, j) for i in range(8, m - 8, every) for j in range(8, m - 8, every)):
        pocket[i:i + 3, j:j + 3] = k
    rows, cols, vals = [], [], []
    for di, dj in ((0, 1), (1, 0)):
        a, b = cell[:m - di, :m - dj].ravel(), cell[di:, dj:].ravel()
        w = np.where(pocket.ravel()[a] == pocket.ravel()[b], rng.uniform(0.5, 2.0, a.size), 0.0)
        rows += [a, b, a, b]
        cols += [b, a, a, b]
        vals += [-w, -w, w, w]
    edge = np.isin(np.arange(m), (0, m - 1))
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m * m,) * 2)
    A = (A + sp.diags(2.0 * (edge[:, None] | edge[None, :]).ravel())).tocsr()
    A.eliminate_zeros()
    b = rng.standard_normal(m * m)
    for k in range(pocket.max() + 1):
        b[pocket.ravel() == k] -= b[pocket.ravel() == k].mean()
    return A, b


case = sys.argv[1]
db = PETSc.Options()
for name, value in [("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                    ("ksp_max_it", "1000"), ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")] + \
        [arg.split("=") for arg in sys.argv[2:]]:
    db[name] = value
if case.startswith("pockets"):
    A, b = pockets(256, {"pockets16": 60, "pockets100": 24}[case])
else:
    A, b = CASES["dmda2d"](40000, 0)
    A = (A * {"scaled1e200": 1e200, "scaled1e-200": 1e-200, "dmda2d": 1.0}[case]).tocsr()
A.sort_indices()
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data))
mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
rhs = mat.createVecLeft()
rhs.array[:] = b
its, reason, setup, solve, relres = solve_once(mat, rhs)
print(f"{case}: {its} iterations, reason {reason}, true relres {relres:.1e}")
