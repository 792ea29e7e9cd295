"""Reading this rank's rows of the DMDA program's MPIAIJ matrix: read_csr (MatMPIAIJGetLocalMat, then a copy of its
arrays, as local_rows did before commit 48420ed) against local_rows (views of the merged rows for the block), min of
10 ms on rank 0 (2026-11-28, this 2-core AMD EPYC, one thread per rank). From the repository root:
    mpiexec -n 2 python results/renew-20261128/rows.py SIDE
"""
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from petsc_htp.petscmat import local_rows, read_csr  # noqa: E402
from petsc_htp.scenes import dmda  # noqa: E402


def best(f, repeats=10):
    """The least ms of ``repeats`` calls of ``f``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(1e3 * (time.perf_counter() - t0))
    return min(times)


def view():
    with local_rows(A) as rows:
        return rows.nnz


side = int(sys.argv[1])
da = dmda.grid(side, 2)
A = dmda.operator(da, 1000.0, 0)
PETSc.Sys.Print(f"{side}^2 on {PETSc.COMM_WORLD.size} ranks: read_csr (a copy) {best(lambda: read_csr(A)):.1f} ms, "
                f"local_rows (views) {best(view):.1f} ms")
A.destroy()
da.destroy()
