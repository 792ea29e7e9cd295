"""Run under ``mpiexec -n 2`` by tests/test_foreign.py: a 2-D DMDA-style matrix of 40 000 rows on one KSP, split
over the ranks, then the same matrix as a new Mat with every row on rank 0 (KSPReset between, no second
KSPSetFromOptions). The second must not keep the first's choice (a rank without rows takes a whole factor: the kept
choice had left the empty rank to the V-cycles, which raised there while rank 0 waited). Prints ``<frame> <reason>
<setup type> <kept>`` on rank 0."""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.scenes.foreign import dmda  # noqa: E402
from bad_input_cases import dist, htp_ksp, rhs  # noqa: E402

A, b = dmda(2, 200, 1e3, 0)
ksp = htp_ksp("kc_")
for k, rows_on in enumerate((None, [A.shape[0], 0])):
    mat = dist(A, rows_on=rows_on)
    if k:
        ksp.reset()
    ksp.setOperators(mat, mat)
    if not k:
        ksp.setFromOptions()
    bv = rhs(mat, b)
    x = bv.duplicate()
    ksp.solve(bv, x)
    ctx = ksp.getPC().getPythonContext()
    PETSc.Sys.Print(k, ksp.getConvergedReason(), type(ctx.setup).__name__, "kept" in ctx.variant.note)
