"""Rotated anisotropy: HTPPC as it comes (ICC(0) of the whole matrix, of each rank's block on several, where the rows'
positive couplings weigh 0.15 of the diagonal (0.2 until d746382) and ICC(0)'s trial confirms;
petsc_htp.twolevel.incomplete),
HTPPC's two-level method (-htp_direct_max 0: what HTPPC did on these matrices before), ICC(0) alone (PCBJACOBI's,
one block per rank) and GAMG (PETSc's defaults), one solve
each from a fresh Mat and KSP after a warm-up solve, CG to rtol 1e-8 in the unpreconditioned norm: setup + solve ms
(iterations) [true relative residual]. Cases: the foreign study's two rotated anisotropies, PyAMG's FE stencils that
pass the trial, and matrices whose positive couplings weigh as much but fail it (eps 0.1, 2-D elasticity, a
Laplacian squared plus the Laplacian): there the trial is what HTPPC pays over its two-level method. Named on the
command line only: cases the rule leaves to the two-level method (grid-aligned FD anisotropy and 3-D anisotropy,
which since ff0f692 a rule of their own takes up to 131 072 rows, the 45-degree case numbered at random), and the
45-degree case with penalty rows (every 300th, 1e30).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [METHODS=htppc,icc] [mpiexec -n 2] \
        python results/rotated-20261127/run.py [N] [case ...]
"""
import os
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from pyamg.gallery import diffusion_stencil_2d, linear_elasticity, poisson, stencil_grid

from petsc_htp.bench.foreigncases import CASES

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "units-20261127"))
import run as units  # noqa: E402

units.METHODS.clear()
units.METHODS.update({"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"},
                      "two-level": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_direct_max": 0},
                      "icc": {"pc_type": "bjacobi", "sub_pc_type": "icc"}, "gamg": {"pc_type": "gamg"}})


def stencil(kind, eps, degrees):
    """PyAMG's rotated diffusion stencil on an n-row grid."""
    return lambda n: stencil_grid(diffusion_stencil_2d(eps, np.radians(degrees), kind), (int(round(n ** 0.5)),) * 2,
                                  format="csr")


EXTRA = {"FE_0.001_0": stencil("FE", 0.001, 0), "FE_0.01_15": stencil("FE", 0.01, 15),
         "FE_0.01_30": stencil("FE", 0.01, 30), "FE_0.001_30": stencil("FE", 0.001, 30),
         "FD_0.1_30": stencil("FD", 0.1, 30), "FE_0.3_0": stencil("FE", 0.3, 0),
         "FD_0.1_45": stencil("FD", 0.1, 45), "FE_0.1_0": stencil("FE", 0.1, 0),
         "elasticity": lambda n: linear_elasticity((int(round((n / 2) ** 0.5)),) * 2, format="csr")[0],
         "laplacian2+laplacian": lambda n: (lambda L: L @ L + L)(poisson((int(round(n ** 0.5)),) * 2, format="csr")),
         "FD_0.001_0": stencil("FD", 0.001, 0), "FD_0.01_0": stencil("FD", 0.01, 0),
         "aniso3d_z0.001": lambda n: (lambda p: sp.kronsum(sp.kronsum(p, p), 1e-3 * p).tocsr())(
             poisson((int(round(n ** (1 / 3))),), format="csr")),
         "shuffled_e0.001_a45": lambda n: shuffled(CASES["aniso_e0.001_a45"](n, 0)[0]),
         "penalty_e0.001_a45": lambda n: penalty(CASES["aniso_e0.001_a45"](n, 0)[0])}
NOT_RUN_BY_DEFAULT = ("FD_0.001_0", "FD_0.01_0", "aniso3d_z0.001", "shuffled_e0.001_a45", "penalty_e0.001_a45", "FE_0.01_30",
                      "FE_0.001_30", "FD_0.1_30", "FE_0.3_0")     # the cases the rule leaves out


def penalty(A):
    """``A`` with every 300th row held by a penalty of 1e30 times the largest diagonal."""
    A = sp.csr_matrix(A)
    return (A + sp.diags(A.diagonal().max() * 1e30 * (np.arange(A.shape[0]) % 300 == 0))).tocsr()


def shuffled(A):
    """``A`` with its rows and columns in a random order."""
    p = np.random.default_rng(0).permutation(A.shape[0])
    return sp.csr_matrix(A)[p][:, p].tocsr()


def with_rhs(make):
    """A case of the foreign study's kind (n, frame) -> (A, b) from ``make(n)``, b standard normal."""
    def case(n, frame):
        A = make(n)
        return A, np.random.default_rng(1).standard_normal(A.shape[0])
    return case


def alone(A, b):
    return {"A": (A, b)}


def main(default_cases):
    """The table of the command line's N and cases (default ``default_cases``) for the methods named in $METHODS
    (default all four)."""
    if os.environ.get("METHODS"):
        keep = os.environ["METHODS"].split(",")
        for name in [m for m in units.METHODS if m not in keep]:
            del units.METHODS[name]
    units.table(alone, default_cases)


if __name__ == "__main__":
    units.CASES.update({name: with_rhs(make) for name, make in EXTRA.items()})
    main(["aniso_e0.01_a30", "aniso_e0.001_a45", *(c for c in EXTRA if c not in NOT_RUN_BY_DEFAULT)])
