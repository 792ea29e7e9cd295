"""The multilevel range check's two ways to see that no component of the DMDA program's matrix is null: the connected
components of A (ranges.components, before commit cfc12c4) against the coarsest operator's components with the
grounded rows lifted through the hierarchy (ranges.floating: none floating), min of 5 ms on rank 0 (2026-11-28, this
2-core AMD EPYC, one thread per rank). From the repository root:
    mpiexec -n R python results/renew-20261128/ranges.py SIDE
"""
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from petsc_htp.collective import Collective  # noqa: E402
from petsc_htp.multilevel.hierarchy import Hierarchy  # noqa: E402
from petsc_htp.multilevel.ranges import components, floating  # noqa: E402
from petsc_htp.petscmat import local_rows  # noqa: E402
from petsc_htp.scenes import dmda  # noqa: E402
from petsc_htp.twolevel.csr import row_sums  # noqa: E402
from petsc_htp.twolevel.nullspace import vanishing  # noqa: E402


def best(f, repeats=5):
    """The least ms of ``repeats`` calls of ``f`` between barriers, and its last result."""
    times = []
    for _ in range(repeats):
        PETSc.COMM_WORLD.barrier()
        t0 = time.perf_counter()
        out = f()
        PETSc.COMM_WORLD.barrier()
        times.append(1e3 * (time.perf_counter() - t0))
    return min(times), out


side = int(sys.argv[1])
da = dmda.grid(side, 2)
A = dmda.operator(da, 1000.0, 0)
coll = Collective(A.getComm())
with local_rows(A) as rows:
    grounded = ~vanishing(row_sums(rows.indptr, rows.data), rows.diagonal(k=A.getOwnershipRange()[0]))
    hierarchy = Hierarchy(A)
    t_comp, (count, _) = best(lambda: components(A, rows, coll))
    t_lift, rows_floating = best(lambda: floating(hierarchy, grounded, coll))
    hierarchy.destroy()
PETSc.Sys.Print(f"{side}^2 on {coll.size} rank(s): components of A {t_comp:.1f} ms ({count} components); "
                f"coarsest components with grounded rows lifted {t_lift:.2f} ms (floating: {len(rows_floating)})")
A.destroy()
da.destroy()
