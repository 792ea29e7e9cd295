"""Two unrelated value sets of one pattern in turn on one KSP (a new user's sweep, 2026-11-27): 5-point finite
volumes on n x n cells with Dirichlet walls, a smooth conductivity of contrast 1e6 and a cell-wise random one
10^U(-3, 3); CG + HTPPC to rtol 1e-8 (unpreconditioned norm), frames smooth, random, smooth, random, smooth, random
on one Mat and KSP, and the random one on a fresh KSP. Prints each frame's iterations and the analyses so far.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python results/sweep-20261127/turns.py [n]
"""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
import test_foreign as t  # noqa: E402

import petsc_htp  # noqa: E402

if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 256
    x = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(x, x, indexing="ij")
    smooth = t._cells(1e6 ** ((np.sin(2 * np.pi * X) * np.sin(3 * np.pi * Y) + np.cos(5 * np.pi * X * Y) + 2) / 4))
    rough = t._cells(10 ** np.random.default_rng(8).uniform(-3, 3, (n, n)))
    b = np.random.default_rng(1).standard_normal(n * n)
    print(f"# {n * n} rows; petsc_htp {petsc_htp.__file__}")
    print(f"random, fresh KSP: {t.solve(rough, b)[1]} iterations")
    _, its, _, ksp, mat = t.solve(smooth, b)
    print(f"frame 0 smooth: {its} iterations")
    for k, (name, A) in enumerate((("random", rough), ("smooth", smooth)) * 2 + (("random", rough),), 1):
        mat.setValuesCSR(A.indptr, A.indices, A.data)
        mat.assemble()
        its = t.solve(A, b, mat=mat, ksp=ksp)[1]
        print(f"frame {k} {name}: {its} iterations, {ksp.getPC().getPythonContext().analysis_count} analyses")
