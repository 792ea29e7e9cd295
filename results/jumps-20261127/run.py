"""3-D coefficient jumps and the coarse V-cycles' Chebyshev bound: HTPPC as it comes (its GAMG coarse solve's
Chebyshev smoothers reach a multiple of GAMG's estimate of the largest eigenvalue, made by some iterations:
sizing.SAFE_SMOOTHER) against other pairs ($BOUNDS, BOUNDxITERATIONS, default 1.1x10, PETSc's, the pair before:
``-htp_cs_mg_levels_ksp_chebyshev_esteig 0,0.1,0,1.1 -htp_cs_pc_gamg_esteig_ksp_max_it 10``), CG to rtol 1e-8 in the unpreconditioned
norm, a fresh Mat and KSP per solve (setup + solve ms (iterations) [true relres] and PETSc's reason where not
converged). ``cubes``: the foreign module's finite volumes with 60 random cubes (scenes.foreign.cubes) at several
sizes, contrasts and seeds; ``foreign N case ...``: the foreign study's matrices, median of 3 after a warm-up.
Any number of ranks.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [BOUNDS=1.5x10,1.1x10] [mpiexec -n 2] python results/jumps-20261127/run.py cubes
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/jumps-20261127/run.py foreign N case ...
"""
import os
import sys

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "units-20261127"))
import run as units  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.scenes.foreign import cubes  # noqa: E402

HTPPC = {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
units.METHODS.clear()
units.METHODS.update({"as it comes": HTPPC})
for pair in os.environ.get("BOUNDS", "1.1x10").split(","):      # others: $BOUNDS, e.g. 1.5x10,1.1x20
    bound, its = pair.split("x")
    units.METHODS[f"bound {bound}, {its} its"] = {**HTPPC, "htp_cs_mg_levels_ksp_chebyshev_esteig": f"0,0.1,0,{bound}",
                                                  "htp_cs_pc_gamg_esteig_ksp_max_it": its}


def cell(result):
    ms, its, rel, reason = result
    return f"{ms:.0f} ({its}) [{rel:.1e}]" + ("" if reason > 0 else f" reason {reason}")


def table(rows):
    """Print a markdown table of ``rows`` ((label, matrix, rhs, repeats), ...), one column per method."""
    PETSc.Sys.Print(f"# {units.COMM.getSize()} rank(s); ms (iterations) [true relres]", comm=units.COMM)
    PETSc.Sys.Print("| matrix | " + " | ".join(units.METHODS) + " |\n|:---|" + "---:|" * len(units.METHODS),
                    comm=units.COMM)
    for label, A, b, repeats in rows:
        cells = []
        for method in units.METHODS:
            runs = [units.solve(A, b, method) for _ in range(repeats)]
            best = runs[int(np.argsort([r[0] for r in runs])[len(runs) // 2])]
            cells.append(cell(best))
        PETSc.Sys.Print(f"| {label} | " + " | ".join(cells) + " |", comm=units.COMM)


if __name__ == "__main__":
    if sys.argv[1] == "cubes":
        grid = [(44, k, s) for k in (1e4, 1e6, 1e10) for s in range(1, 7)] + [(64, 1e6, s) for s in range(5, 9)]
        table((f"{side}^3, contrast {k:g}, seed {s}", *cubes(side, k, 60, s), 1) for side, k, s in grid)
    else:
        n = int(sys.argv[2])
        for case in sys.argv[3:]:
            A, b = CASES[case](n, 0)[:2]
            units.solve(A, b, "as it comes")                         # warm-up
        table((f"{case}, {CASES[case](n, 0)[0].shape[0]} rows", *CASES[case](n, 0)[:2], 3) for case in sys.argv[3:])
