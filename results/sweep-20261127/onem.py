"""The foreign study's 2-D DMDA matrix at 1 048 576 rows, one solve by CG + HTPPC as it comes (rtol 1e-8, unpreconditioned
norm) from a fresh Mat and KSP, after a warm-up: setup + solve ms of two, iterations, true relative residual.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/sweep-20261127/onem.py
"""
import os
import sys

import petsc4py
petsc4py.init(sys.argv[:1])
from petsc4py import PETSc
import scipy.sparse as sp
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "units-20261127"))
import run as units
import petsc_htp
from petsc_htp.bench.foreigncases import CASES
units.METHODS.clear(); units.METHODS["m"] = {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}
A, b = CASES["dmda2d"](1048576, 0)[:2]; A = sp.csr_matrix(A)
units.solve(A, b, "m")
r = [units.solve(A, b, "m") for _ in range(2)]
PETSc.Sys.Print(petsc_htp.__file__, "ranks", PETSc.COMM_WORLD.size, "ms", [round(x[0]) for x in r], "its", r[0][1], "relres %.1e" % r[0][2])
