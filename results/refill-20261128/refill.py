"""The V-cycles' reordered copy P = A[perm][:, perm] of a P1 triangle mesh numbered at random (the foreign study's
fem_tri): made by PETSc's MatCreateSubMatrix against multilevel.reordered.Reordered (one sort of A's entries), and
made again for frame 1's values by MatCreateSubMatrix into the kept P against Reordered.refill's gather; median and
least ms of REPS, one thread. From the repository root:  python results/refill-20261128/refill.py N REPS"""
import statistics
import sys
import time

import petsc4py

petsc4py.init([sys.argv[0]])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.multilevel.reordered import Reordered  # noqa: E402
from petsc_htp.petscmat import local_rows  # noqa: E402

n, reps = int(sys.argv[1]), int(sys.argv[2])
A = CASES["fem_tri"](n, 0)[0].tocsr()
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr, A.indices, A.data), comm=PETSc.COMM_SELF)
perm = np.random.default_rng(0).permutation(A.shape[0])
order = PETSc.IS().createGeneral(perm.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
B = CASES["fem_tri"](n, 1)[0].tocsr()
times = {key: [] for key in ("made by MatCreateSubMatrix", "made by Reordered", "new values by MatCreateSubMatrix",
                             "new values by Reordered.refill")}
for _ in range(reps):
    mat.setValuesCSR(A.indptr, A.indices, A.data)
    mat.assemble()
    with local_rows(mat) as rows:
        t0 = time.perf_counter()
        Q = mat.createSubMatrix(order, order)
        t1 = time.perf_counter()
        made = Reordered(mat, rows, perm, order)
        t2 = time.perf_counter()
    mat.setValuesCSR(B.indptr, B.indices, B.data)
    mat.assemble()
    with local_rows(mat) as rows:
        t3 = time.perf_counter()
        mat.createSubMatrix(order, order, submat=Q)
        t4 = time.perf_counter()
        made.refill(rows)
        t5 = time.perf_counter()
    for key, dt in zip(times, (t1 - t0, t2 - t1, t4 - t3, t5 - t4)):
        times[key].append(1e3 * dt)
    same = Q.equal(made.P)
    Q.destroy()
    made.P.destroy()
print(f"{A.shape[0]} rows, {A.nnz} entries; the copies agree entry for entry: {same}")
for key, ms in times.items():
    print(f"{key}: median {statistics.median(ms):.1f} ms, least {min(ms):.1f}")
