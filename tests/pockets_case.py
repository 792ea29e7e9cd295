"""Run under ``mpiexec -n 1`` and ``-n 2`` by tests/test_multilevel.py: a closed 2-D domain of 96^2 cells holding 49
sealed pockets of 3x3 cells (no coupling to the rest: each a null component of its own, its right-hand side of zero
mean there), the rest held by Dirichlet walls, handed over bare to CG and HTPPC's V-cycles (``-htp_variant
multilevel``, each smoother in turn). Prints ``<smoother> <reason> <iterations> <true relative residual>`` on rank 0."""
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bad_input_cases import dist, solve  # noqa: E402

M, SIDE, EVERY = 96, 3, 12
cell = np.arange(M * M).reshape(M, M)
pocket = np.full((M, M), -1)
for k, (i, j) in enumerate((i, j) for i in range(8, M - 8, EVERY) for j in range(8, M - 8, EVERY)):
    pocket[i:i + SIDE, j:j + SIDE] = k
rng = np.random.default_rng(3)
rows, cols, vals = [], [], []
for di, dj in ((0, 1), (1, 0)):
    a, b = cell[:M - di, :M - dj].ravel(), cell[di:, dj:].ravel()
    w = np.where(pocket.ravel()[a] == pocket.ravel()[b], rng.uniform(0.5, 2.0, a.size), 0.0)
    rows += [a, b, a, b]
    cols += [b, a, a, b]
    vals += [-w, -w, w, w]
wall = (np.isin(np.arange(M), (0, M - 1))[:, None] | np.isin(np.arange(M), (0, M - 1))[None, :]).ravel()
A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(M * M,) * 2)
A = (A + sp.diags(2.0 * wall)).tocsr()
A.eliminate_zeros()
b = rng.standard_normal(M * M)
inside = pocket.ravel()
for k in range(inside.max() + 1):
    b[inside == k] -= b[inside == k].mean()
mat = dist(A)
for smoother in ("gs", "jacobi", "leaves"):
    reason, its, relres, _ = solve(mat, b, {"htp_variant": "multilevel", "htp_direct_max": 0, "htp_ml_coarse_max": 300,
                                        "htp_ml_smoother": smoother})
    PETSc.Sys.Print(smoother, reason, its, f"{relres:.1e}")
