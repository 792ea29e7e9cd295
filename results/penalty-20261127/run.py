"""Penalty Dirichlet rows: the foreign study's matrices with every (N/300)-th row held by a penalty, a_ii + tgv x the
largest diagonal (tgv 1e8 and FreeFEM's 1e30), solved once each by CG + HTPPC (as it comes) and CG + GAMG (PETSc's
defaults), fresh Mat and KSP, rtol 1e-8 in the unpreconditioned norm: setup + solve ms, iterations and the true
relative residual (a CG that stops "converged" above 1e-8 there returned a wrong answer).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/penalty-20261127/run.py [N] [case ...]
"""
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "units-20261127"))
from run import table  # noqa: E402


def held(A, b):
    """A with every (N/300)-th row held by a penalty of tgv times the largest diagonal."""
    rows = np.zeros(A.shape[0])
    rows[::max(1, A.shape[0] // 300)] = A.diagonal().max()
    return {f"tgv {tgv:g}": ((A + sp.diags(tgv * rows)).tocsr(), b) for tgv in (0.0, 1e8, 1e30)}


if __name__ == "__main__":
    table(held, ["dmda3d", "free_surface", "fem_tri", "fem_tet", "lognormal", "neumann"])
