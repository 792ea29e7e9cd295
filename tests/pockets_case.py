"""Run under ``mpiexec -n 1`` and ``-n 2`` by tests/test_multilevel.py: a closed 2-D domain of 96^2 cells holding 49
sealed pockets of 3x3 cells and one across the two ranks' rows (:func:`petsc_htp.scenes.foreign.pockets`: each a null
component of its own, its right-hand side of zero mean there), the rest held by Dirichlet walls, handed over bare to
CG and HTPPC's V-cycles (``-htp_variant multilevel``, a coarsest size of 300 rows, each smoother in turn). Prints
``<smoother> <reason> <iterations> <true relative residual>`` on rank 0."""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.scenes.foreign import pockets  # noqa: E402
from bad_input_cases import dist, solve  # noqa: E402

A, b = pockets(96, 12, extra=[(47, 42)])             # rows 47-49 of the grid: 2 ranks split at grid row 48
mat = dist(A)
for smoother in ("gs", "jacobi", "leaves"):
    reason, its, relres, _ = solve(mat, b, {"htp_variant": "multilevel", "htp_direct_max": 0, "htp_ml_coarse_max": 300,
                                            "htp_ml_smoother": smoother})
    PETSc.Sys.Print(smoother, reason, its, f"{relres:.1e}")
