"""The finest level's products on a foreign study case's matrix taken in its leaves' order, the leaves as the
aggregation numbers them ('argsort') and renumbered by level.banded_leaves ('rcm'): the median |i - j| of A's and
W's entries, nnz per row, the level's set-up and the products A W and W^T (A W) alone (min of three), one thread
(2026-11-28, this 2-core AMD EPYC). From the repository root:
    python results/bound-20261128/products.py CASE N"""
import sys
import time

import petsc4py

petsc4py.init([])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.multilevel.level import Level, banded_leaves, leaves  # noqa: E402
from petsc_htp.petscmat import local_rows, read_csr  # noqa: E402


def best(f, reps=3):
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        out = f()
        times.append(1e3 * (time.perf_counter() - t0))
    return min(times), out


case, n = sys.argv[1], int(sys.argv[2])
A, _ = CASES[case](n, 0)
A = A.tocsr()
A.sort_indices()
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data))
with local_rows(mat) as rows:
    leaf = leaves(mat, rows)
    labels = {"argsort": leaf, "rcm": banded_leaves(mat, rows, leaf)}
for name, label in labels.items():
    perm = np.argsort(label, kind="stable").astype(PETSc.IntType)
    order = PETSc.IS().createGeneral(perm)
    P = mat.createSubMatrix(order, order)
    t0 = time.perf_counter()
    level = Level(P, leaf=label[perm], blocks=False)
    setup = 1e3 * (time.perf_counter() - t0)
    Ap, W = read_csr(P), read_csr(level.W)
    t_aw, AW = best(lambda: Ap @ W)
    t_c, _ = best(lambda: W.T.tocsr() @ AW)
    span = np.median(np.abs(Ap.indices - np.repeat(np.arange(Ap.shape[0]), np.diff(Ap.indptr))))
    C = read_csr(level.below)
    cspan = np.median(np.abs(C.indices - np.repeat(np.arange(C.shape[0]), np.diff(C.indptr))))
    print(f"{case} N={n} {name}: A span {span:.0f}, coarse operator {C.shape[0]} rows span {cspan:.0f}; W nnz/row "
          f"{W.nnz / W.shape[0]:.2f}; level {setup:.0f} ms, A W {t_aw:.1f} ms, W^T (A W) {t_c:.1f} ms")
