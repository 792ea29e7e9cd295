"""A 2-D grid whose nodes are joined at random to far ones (a new user's sweep, 2026-11-27): the 5-point graph
Laplacian of a side x side grid, a share of its nodes each joined to a random other node (weight 1), + 0.01 I; one
solve each by CG to rtol 1e-8 in the unpreconditioned norm with HTPPC as it comes and PETSc's GAMG at its defaults, a
fresh Mat and KSP, after a warm-up of each. Prints setup + solve ms (iterations) [true relres] and HTPPC's coarse
solve line of -ksp_view.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/sweep-20261127/shortcuts.py [side]
"""
import os
import sys

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "units-20261127"))
import run as units  # noqa: E402

import petsc_htp  # noqa: E402


def shortcuts(side, share, seed=11):
    """(A, b): the grid's Laplacian with ``share`` of its nodes joined at random, + 0.01 I; b standard normal."""
    n = side * side
    grid = np.arange(n).reshape(side, side)
    a, c = np.random.default_rng(seed).integers(0, n, (2, int(share * n)))
    rows = np.concatenate([grid[:-1].ravel(), grid[:, :-1].ravel(), a])
    cols = np.concatenate([grid[1:].ravel(), grid[:, 1:].ravel(), c])
    keep = rows != cols
    W = sp.csr_matrix((np.ones(keep.sum()), (rows[keep], cols[keep])), shape=(n, n))
    W = W + W.T
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel() + 1e-2) - W).tocsr(), np.random.default_rng(1).standard_normal(n)


if __name__ == "__main__":
    side = int(sys.argv[1]) if len(sys.argv) > 1 else 316
    units.METHODS.clear()
    units.METHODS.update({"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"}, "gamg": {"pc_type": "gamg"}})
    PETSc.Sys.Print(f"# {units.COMM.getSize()} rank(s), {side}^2 rows; ms (iterations) [true relres]; "
                    f"petsc_htp {petsc_htp.__file__}", comm=units.COMM)
    for method in units.METHODS:
        units.solve(*shortcuts(64, 0.01), method)                                  # warm-up
    for share in (0.0, 0.001, 0.003, 0.01):
        A, b = shortcuts(side, share)
        cells = []
        for method in units.METHODS:
            ms, its, rel, reason = units.solve(A, b, method)
            cells.append(f"{method} {ms:.0f} ({its}) [{rel:.1e}]" + ("" if reason > 0 else f" reason {reason}"))
        PETSc.Sys.Print(f"{100 * share:g} % joined: " + "; ".join(cells), comm=units.COMM)
