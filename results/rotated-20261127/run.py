"""Rotated anisotropy: HTPPC as it comes (ICC(0) of the whole matrix, of each rank's block on several, where the rows'
positive couplings weigh a fifth of the diagonal and ICC(0)'s trial confirms; petsc_htp.twolevel.incomplete),
HTPPC's two-level method (-htp_direct_max 0: what HTPPC did on these matrices before), ICC(0) alone (PCBJACOBI's,
one block per rank) and GAMG (PETSc's defaults), one solve
each from a fresh Mat and KSP after a warm-up solve, CG to rtol 1e-8 in the unpreconditioned norm: setup + solve ms
(iterations) [true relative residual]. Cases: the foreign study's two rotated anisotropies, PyAMG's FE stencils that
pass the trial, and matrices whose positive couplings weigh as much but fail it (eps 0.1, 2-D elasticity, a
Laplacian squared plus the Laplacian): there the trial is what HTPPC pays over its two-level method.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [mpiexec -n 2] python results/rotated-20261127/run.py [N] [case ...]
"""
import sys
from pathlib import Path

import numpy as np
from pyamg.gallery import diffusion_stencil_2d, linear_elasticity, poisson, stencil_grid

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
         "FD_0.1_45": stencil("FD", 0.1, 45), "FE_0.1_0": stencil("FE", 0.1, 0),
         "elasticity": lambda n: linear_elasticity((int(round((n / 2) ** 0.5)),) * 2, format="csr")[0],
         "laplacian2+laplacian": lambda n: (lambda L: L @ L + L)(poisson((int(round(n ** 0.5)),) * 2, format="csr"))}


def with_rhs(make):
    """A case of the foreign study's kind (n, frame) -> (A, b) from ``make(n)``, b standard normal."""
    def case(n, frame):
        A = make(n)
        return A, np.random.default_rng(1).standard_normal(A.shape[0])
    return case


def alone(A, b):
    return {"A": (A, b)}


if __name__ == "__main__":
    units.CASES.update({name: with_rhs(make) for name, make in EXTRA.items()})
    units.table(alone, ["aniso_e0.01_a30", "aniso_e0.001_a45", *EXTRA])
