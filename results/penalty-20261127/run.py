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
from run import COMM, METHODS, PETSc, solve  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 65536
    cases = sys.argv[2:] or ["dmda3d", "free_surface", "fem_tri", "fem_tet", "lognormal", "neumann"]
    PETSc.Sys.Print(f"# {COMM.getSize()} rank(s), N about {n}; ms (iterations) [true relres], PETSc's reason where "
                    f"not converged; petsc_htp {petsc_htp.__file__}", comm=COMM)
    for case in cases:
        A, b = CASES[case](n, 0)[:2]
        A = sp.csr_matrix(A)
        held = np.zeros(A.shape[0])
        held[::max(1, A.shape[0] // 300)] = A.diagonal().max()
        for method in METHODS:
            solve(A, b, method)                                   # warm-up
            cells = []
            for tgv in (0.0, 1e8, 1e30):
                ms, its, rel, reason = solve((A + sp.diags(tgv * held)).tocsr(), b, method)
                cells.append(f"tgv {tgv:g}: {ms:.0f} ({its}) [{rel:.1e}]" + ("" if reason > 0 else f" reason {reason}"))
            PETSc.Sys.Print(f"{case} {A.shape[0]} {method}: " + "; ".join(cells), comm=COMM)


if __name__ == "__main__":
    main()
