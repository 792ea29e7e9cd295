"""The multilevel set-up's two pieces on the foreign study's 2-D DMDA matrix, timed alone: the hierarchy (leaves,
smoothed coarse vectors, Galerkin operators) and the V-cycle (PCMG, the smoothers' scales, the coarsest factor); min
and median of five builds, one thread (2026-11-28, this 2-core AMD EPYC). From the repository root:
    python results/bound-20261128/pieces.py N [ROOT]      (ROOT: a checkout whose petsc_htp is timed)"""
import sys
import time

if len(sys.argv) > 2:
    sys.path.insert(0, sys.argv[2])
import petsc4py  # noqa: E402

petsc4py.init([])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.multilevel import cycle  # noqa: E402
from petsc_htp.multilevel.hierarchy import Hierarchy  # noqa: E402

n = int(sys.argv[1])
A, _ = CASES["dmda2d"](n, 0)
A = A.tocsr()
A.sort_indices()
M = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data))
th, tc = [], []
for _ in range(5):
    t0 = time.perf_counter()
    H = Hierarchy(M, blocks=False)
    t1 = time.perf_counter()
    pc, scales = cycle.multigrid(H, "pieces_", smoother="jacobi")
    t2 = time.perf_counter()
    th.append(1e3 * (t1 - t0))
    tc.append(1e3 * (t2 - t1))
    pc.destroy()
    H.destroy()
    for level in H.levels:
        level.destroy()
print(f"{petsc_htp.__file__.rsplit('/', 2)[0]} N={n}: hierarchy min {min(th):.1f} median {np.median(th):.1f} ms; "
      f"V-cycle min {min(tc):.1f} median {np.median(tc):.1f} ms; scales {', '.join(f'{s:.2f}' for s in scales)}")
