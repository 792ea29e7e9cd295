"""Run under ``mpiexec -n 2`` by tests/test_multilevel.py: a 2-D grid of 100^2 cells whose edges have log-normal
weights exp(5 N(0, 1)) (Dirichlet walls; strong couplings cross the two ranks' rows), handed over bare to CG and
HTPPC's V-cycles (``-htp_variant multilevel``, a coarsest size of 500 rows). Prints ``<reason> <iterations> <true
relative residual>`` on rank 0."""
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bad_input_cases import dist, solve  # noqa: E402

M = 100
rng = np.random.default_rng(0)
cell = np.arange(M * M).reshape(M, M)
rows, cols, vals = [], [], []
for a, b in ((cell[:, :-1].ravel(), cell[:, 1:].ravel()), (cell[:-1, :].ravel(), cell[1:, :].ravel())):
    w = np.exp(5.0 * rng.standard_normal(a.size))
    rows += [a, b, a, b]
    cols += [b, a, a, b]
    vals += [-w, -w, w, w]
edge = np.isin(np.arange(M), (0, M - 1))
A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(M * M,) * 2)
A = (A + sp.diags((edge[:, None] | edge[None, :]).ravel().astype(float))).tocsr()
reason, its, relres, _ = solve(dist(A), rng.standard_normal(M * M), {"htp_variant": "multilevel", "htp_direct_max": 0,
                                                                      "htp_ml_coarse_max": 500})
PETSc.Sys.Print(reason, its, f"{relres:.1e}")
