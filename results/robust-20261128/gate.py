"""What the V-cycles' row-scaling decision costs on one rank: the sampled neighbours' diagonal spread
(scaling.neighbours_spread) against the quotients it gates (scaling.weights with the pinned rows left out), least of 5,
on the foreign study's dmda2d at 65 536 and 1M rows, itself and as D A D (D = 10^U(-2, 2)). From the repository root:
  python results/robust-20261128/gate.py > results/robust-20261128/gate.txt"""
import timeit

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from petsc_htp.bench.foreigncases import CASES
from petsc_htp.collective import Collective
from petsc_htp.twolevel import dominance, scaling

coll = Collective(PETSc.COMM_SELF)
for n in (65536, 1048576):
    A = CASES["dmda2d"](n, 0)[0].tocsr()
    d = 10.0 ** np.random.default_rng(0).uniform(-2, 2, A.shape[0])
    for name, M in (("A", A), ("D A D", (sp.diags(d) @ A @ sp.diags(d)).tocsr())):
        M.sort_indices()
        gate = min(timeit.repeat(lambda: scaling.neighbours_spread(M, 0, coll), number=1, repeat=5))
        full = min(timeit.repeat(lambda: scaling.weights(M, 0, coll, M, dominance.pinned(M, 0, coll)[0]), number=1,
                                 repeat=5))
        z = scaling.weights(M, 0, coll, M, dominance.pinned(M, 0, coll)[0])[0]
        print(f"dmda2d {n} {name}: spread gate {'passes' if scaling.neighbours_spread(M, 0, coll) else 'stops'} in "
              f"{1e3 * gate:.2f} ms; quotients {1e3 * full:.1f} ms ({'|diag|^-1/2' if z is not None else 'constants'})")
