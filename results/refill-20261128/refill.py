"""New values for the V-cycles' reordered copy P = A[perm][:, perm] of a P1 triangle mesh numbered at random (the
foreign study's fem_tri, frame 1's values): PETSc's MatCreateSubMatrix into the kept P against
multilevel.reordered.Refill's gather, and the map's one-time cost; median and least ms of REPS, one thread. From the
repository root:  python results/refill-20261128/refill.py N REPS"""
import statistics
import sys
import time

import petsc4py

petsc4py.init([sys.argv[0]])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.multilevel.reordered import Refill, value_map  # noqa: E402
from petsc_htp.petscmat import local_rows  # noqa: E402

n, reps = int(sys.argv[1]), int(sys.argv[2])
A = CASES["fem_tri"](n, 0)[0].tocsr()
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
perm = np.random.default_rng(0).permutation(A.shape[0])
order = PETSc.IS().createGeneral(perm.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
P, Q = mat.createSubMatrix(order, order), mat.createSubMatrix(order, order)
B = CASES["fem_tri"](n, 1)[0].tocsr()
mat.setValuesCSR(B.indptr, B.indices, B.data)
mat.assemble()
refill, times = Refill(mat, order, perm, P), {"map": [], "MatCreateSubMatrix": [], "Refill": []}
with local_rows(mat) as rows:
    refill(rows)                                # the map found, once
    for _ in range(reps):
        t0 = time.perf_counter()
        value_map(rows, perm, P)
        t1 = time.perf_counter()
        mat.createSubMatrix(order, order, submat=Q)
        t2 = time.perf_counter()
        refill(rows)
        t3 = time.perf_counter()
        for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
            times[key].append(1e3 * dt)
print(f"{A.shape[0]} rows, {A.nnz} entries; P by the map equals MatCreateSubMatrix's: {P.equal(Q)}")
for key, ms in times.items():
    print(f"{key}: median {statistics.median(ms):.1f} ms, least {min(ms):.1f}")
