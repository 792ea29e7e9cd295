"""Small matrices on several ranks: the foreign study's cases at about N rows and PyAMG's shipped examples, one solve
each by CG to rtol 1e-8 (unpreconditioned norm) from a fresh Mat and KSP, HTPPC as it comes against PETSc's
PCREDUNDANT around its Cholesky and its LU (nested dissection); median setup + solve ms of 5 after a warm-up
(iterations).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 mpiexec -n 2 python results/sweep-20261127/small.py [N]
"""
import os
import sys

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "units-20261127"))
import run as units  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES, pyamg_cases  # noqa: E402

GATHERED = {"pc_type": "redundant", "redundant_pc_factor_mat_ordering_type": "nd"}

if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1500
    units.METHODS.clear()
    units.METHODS.update({"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"},
                          "redundant cholesky": {**GATHERED, "redundant_pc_type": "cholesky"},
                          "redundant lu": {**GATHERED, "redundant_pc_type": "lu"}})
    PETSc.Sys.Print(f"# {units.COMM.getSize()} rank(s); median ms of 5 (iterations); petsc_htp {petsc_htp.__file__}",
                    comm=units.COMM)
    cases = {c: CASES[c](n, 0)[:2] for c in ("dmda2d", "free_surface", "lognormal", "neumann", "fem_tri", "fem_tet")}
    cases.update({k: v[:2] for k, v in pyamg_cases().items()})
    for name, (A, b) in cases.items():
        A, cells = sp.csr_matrix(A), []
        for method in units.METHODS:
            units.solve(A, b, method)
            runs = [units.solve(A, b, method) for _ in range(5)]
            cells.append(f"{method} {np.median([r[0] for r in runs]):.2f} ({runs[0][1]})")
        PETSc.Sys.Print(f"{name} {A.shape[0]}: " + " | ".join(cells), comm=units.COMM)
