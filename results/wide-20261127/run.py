"""Wide rows and chains: HTPPC as it comes (ICC(0) of the whole matrix, of each rank's block on several, where rows
hold at least 20 stored entries whose positive couplings weigh less than 0.15 of the diagonal and ICC(0)'s trial on a
graph ball confirms; one Cholesky factor in reverse Cuthill-McKee order where the graph is a chain;
petsc_htp.whole, petsc_htp.twolevel.incomplete), HTPPC's two-level method (-htp_direct_max 0: what HTPPC did on these
matrices before), ICC(0) alone (PCBJACOBI's, one block per rank) and GAMG (PETSc's defaults): the methods and table of
results/rotated-20261127/run.py, one solve each from a fresh Mat and KSP after a warm-up solve, CG to rtol 1e-8 in
the unpreconditioned norm: setup + solve ms (iterations) [true relative residual]. Cases: Q1 hexahedra (the foreign
study's fem_hex, and its log-normal conductivity, frame 1), a 27-point finite-difference Laplacian, Q1 hexahedra with
conductivity balls of contrast 1e4 (the trial fails them), Q1 elasticity (positive couplings: no trial), a 1-D
Laplacian in its own order and numbered at random, and a strip of 8 x N/8 5-point cells (not caught).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [METHODS=htppc,icc] [mpiexec -n 2] \\
        python results/wide-20261127/run.py [N] [case ...]
"""
import importlib.util
from pathlib import Path

import scipy.sparse as sp

from petsc_htp.bench.foreigncases import CASES
from petsc_htp.scenes import meshes

spec = importlib.util.spec_from_file_location(
    "rotated_run", Path(__file__).resolve().parent.parent / "rotated-20261127" / "run.py")
rotated = importlib.util.module_from_spec(spec)       # its four methods, its table
spec.loader.exec_module(rotated)


def line(n):
    """The 1-D Laplacian of n rows (Dirichlet ends)."""
    return sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (n, n)).tocsr()


def lap27(n):
    """The 27-point Laplacian (off-diagonals -1, diagonal 26) on a grid of about n rows."""
    m = int(round(n ** (1 / 3)))
    one = sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], (m, m))
    return (27.0 * sp.identity(m ** 3) - sp.kron(sp.kron(one, one), one)).tocsr()


EXTRA = {"hex_lognormal": lambda n: CASES["fem_hex"](n, 1)[0], "fd27": lap27,
         "hex_balls_1e4": lambda n: meshes.q1_laplacian(n, 0, 1e4)[0],
         "q1_elasticity": lambda n: meshes.q1_elasticity(int(round((n / 3) ** (1 / 3))))[0],
         "chain": line, "chain_shuffled": lambda n: rotated.shuffled(line(n)),
         "strip8": lambda n: (sp.kronsum(line(8), line(n // 8))).tocsr()}

if __name__ == "__main__":
    rotated.units.CASES.update({name: rotated.with_rhs(make) for name, make in EXTRA.items()})
    rotated.main(["fem_hex", *EXTRA])
