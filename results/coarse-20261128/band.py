"""Set-up and one solve of the multilevel hierarchy's coarsest operator by PETSc's sparse LU (nested dissection, as
the V-cycle's coarse solve had it) and by LAPACK's banded Cholesky (twolevel.band.BandPC, reverse Cuthill-McKee):
the DMDA matrix (petsc_htp.scenes.dmda) of side N in DIM dimensions, its hierarchy down to COARSE rows; best of
three set-ups, twenty solves each. From the repository root:
    python results/coarse-20261128/band.py N COARSE [DIM]
"""
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init([])
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from petsc_htp.multilevel.hierarchy import Hierarchy  # noqa: E402
from petsc_htp.petscmat import local_rows  # noqa: E402
from petsc_htp.scenes import dmda  # noqa: E402
from petsc_htp.twolevel.band import BandPC, ordering  # noqa: E402


def timed(C, kind):
    """(best set-up ms, its solve ms) of ``kind`` on ``C``."""
    best = None
    for _ in range(3):
        pc = PETSc.PC().create()
        pc.setOperators(C, C)
        if kind == "lu":
            pc.setType("lu")
            pc.setFactorOrdering("nd")
            pc.setFactorShift(PETSc.Mat.FactorShiftType.NONZERO)
        else:
            pc.setType("python")
            pc.setPythonContext(BandPC())
        t0 = time.perf_counter()
        pc.setUp()
        setup = time.perf_counter() - t0
        x, y = C.createVecs()
        x.setRandom()
        t0 = time.perf_counter()
        for _ in range(20):
            pc.apply(x, y)
        solve = (time.perf_counter() - t0) / 20
        for obj in (pc, x, y):
            obj.destroy()
        best = min(best or (setup, solve), (setup, solve))
    return 1e3 * best[0], 1e3 * best[1]


def main():
    n, coarse = int(sys.argv[1]), int(sys.argv[2])
    dim = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    A = dmda.operator(dmda.grid(n, dim), 1000.0, 0)
    h = Hierarchy(A, coarse_max=coarse, blocks=False)
    C = h.coarsest
    with local_rows(C) as rows:
        width = ordering(rows)[3]
    lu, band = timed(C, "lu"), timed(C, "band")
    print(f"{dim}-D side {n}: coarsest {C.getSize()[0]} rows, {C.getInfo()['nz_used'] / C.getSize()[0]:.1f} a row, "
          f"band {width} wide; set-up ms LU {lu[0]:.1f} band {band[0]:.1f}; solve ms LU {lu[1]:.3f} band {band[1]:.3f}")
    h.destroy()
    A.destroy()


if __name__ == "__main__":
    main()
