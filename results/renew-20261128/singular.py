"""Bare singular matrices under the multilevel V-cycles (nothing attached, b in the range, CG to rtol 1e-8 on the
unpreconditioned residual, at most 300 iterations): a Neumann square of contrast C (foreign.neumann) alone and beside a
Dirichlet square (foreign.lognormal), 100^2 rows each, -htp_variant multilevel -htp_direct_max 0 -htp_ml_coarse_max
200; PETSc's reason, iterations and the true relative residual (2026-11-28, this 2-core AMD EPYC, one thread). From the
repository root, for the code at ROOT (default this checkout):
    python results/renew-20261128/singular.py [ROOT]
"""
import sys
from pathlib import Path

import numpy as np
import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, sys.argv[1] if len(sys.argv) > 1 else str(Path(__file__).resolve().parents[2]))
import scipy.sparse as sp  # noqa: E402

from petsc_htp.scenes import foreign  # noqa: E402

OPTIONS = {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": 1e-8, "ksp_max_it": 300,
           "pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_variant": "multilevel", "htp_direct_max": 0,
           "htp_ml_coarse_max": 200}


def solve(A, b):
    """(reason, iterations, true relative residual) of the bare ``A`` x = ``b``."""
    A = sp.csr_matrix(A)
    A.sort_indices()
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
    rhs, x = mat.createVecs()
    rhs.getArray()[:] = b
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOptionsPrefix("singular_")
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    ksp.solve(rhs, x)
    out = ksp.getConvergedReason(), ksp.getIterationNumber(), np.linalg.norm(A @ x.getArray() - b) / np.linalg.norm(b)
    for obj in (ksp, mat, rhs, x):
        obj.destroy()
    return out


for key, value in OPTIONS.items():
    PETSc.Options("singular_")[key] = value
for contrast, seeds in ((1e6, range(3)), (1e8, range(2)), (1e10, range(2))):
    for seed in seeds:
        N = foreign.neumann(100, contrast, seed)[0]
        D = foreign.lognormal(100, contrast, seed)[0]
        for name, A in (("beside a Dirichlet square", sp.block_diag([N, D])), ("alone", N)):
            b = np.random.default_rng(seed).standard_normal(A.shape[0])
            b[:N.shape[0]] -= b[:N.shape[0]].mean()
            reason, its, relres = solve(A, b)
            print(f"contrast {contrast:.0e} seed {seed}, the Neumann square {name}: reason {reason}, {its} iterations, "
                  f"true relative residual {relres:.1e}")
