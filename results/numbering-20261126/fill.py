"""The leaf factor of aggregation leaves whose rows A's numbering scatters: each leaf's rows in A's (random) order
against leaves.by_degree, on the foreign study's free surface (permuted at random), P1 triangles and P1 tets (their
nodes numbered at random) at about 64k rows: the Cholesky factor's values (natural ordering, as HTPPC factors D)
and the median ms of 30 applications.

    OMP_NUM_THREADS=1 python results/numbering-20261126/fill.py > results/numbering-20261126/fill.txt
"""
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(["fill"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.twolevel.aggregation import aggregates  # noqa: E402
from petsc_htp.twolevel.leaves import by_degree  # noqa: E402


def factor(A, perm, part):
    """(values in the Cholesky factor of the leaf blocks of A in the order ``perm``, median ms of a solve)."""
    P = A[perm][:, perm].tocoo()
    inside = part[perm][P.row] == part[perm][P.col]
    D = sp.csr_matrix((P.data[inside], (P.row[inside], P.col[inside])), shape=A.shape)
    D.sort_indices()
    mat = PETSc.Mat().createAIJ(D.shape, csr=(D.indptr.astype(PETSc.IntType), D.indices.astype(PETSc.IntType),
                                              D.data), comm=PETSc.COMM_SELF)
    pc = PETSc.PC().create(PETSc.COMM_SELF)
    pc.setOperators(mat, mat)
    pc.setType("cholesky")
    pc.setFactorOrdering("natural")
    pc.setUp()
    x, y = mat.createVecs()
    x.setRandom()
    times = []
    for _ in range(30):
        t = time.perf_counter()
        pc.apply(x, y)
        times.append(1e3 * (time.perf_counter() - t))
    return int(pc.getFactorMatrix().getInfo()["nz_used"]), float(np.median(times))


for case, second in (("free_surface", "pairs"), ("fem_tri", "standard"), ("fem_tet", "standard")):
    A, _ = CASES[case](65536, 0)
    if case == "free_surface":                                   # grid order: permuted at random here
        p = np.random.default_rng(0).permutation(A.shape[0])
        A = sp.csr_matrix(A[p][:, p])
        A.sort_indices()
    part = aggregates(A, second=second)
    stable = np.argsort(part, kind="stable")
    (n0, t0), (n1, t1) = factor(A, stable, part), factor(A, by_degree(A, part, stable), part)
    print(f"{case} N={A.shape[0]}: A's order {n0} values, {t0:.3f} ms; by degree {n1} values, {t1:.3f} ms")
