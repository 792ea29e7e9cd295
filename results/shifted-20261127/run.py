"""Shifted rows: one backward-Euler step of the heat equation, M + dt K with P1 elements on unstructured triangles
and tetrahedra (petsc_htp.scenes.meshes.p1_heat, dt = s h^2), and the same grid matrices with no shift. HTPPC as it
comes (ICC(0) of the whole matrix, of each rank's block on several, where the median row's sum is 0.0025 of its
diagonal and ICC(0)'s trial on a graph ball of 8 192 rows confirms; petsc_htp.twolevel.incomplete), HTPPC's
two-level method (-htp_direct_max 0: what HTPPC did on these matrices before), ICC(0) alone (PCBJACOBI's, one block
per rank) and GAMG (PETSc's defaults), one solve each from a fresh Mat and KSP after a warm-up solve, CG to rtol
1e-8 in the unpreconditioned norm: setup + solve ms (iterations) [true relative residual].

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [METHODS=htppc,icc] [mpiexec -n 2] \
        python results/shifted-20261127/run.py [N] [case ...]
"""
import os
import sys
from pathlib import Path

from petsc_htp.scenes.meshes import p1_heat

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "units-20261127"))
import run as units  # noqa: E402

units.METHODS.clear()
units.METHODS.update({"htppc": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC"},
                      "two-level": {"pc_type": "python", "pc_python_type": "petsc_htp.HTPPC", "htp_direct_max": 0},
                      "icc": {"pc_type": "bjacobi", "sub_pc_type": "icc"}, "gamg": {"pc_type": "gamg"}})
HEAT = {f"heat_{name}_{steps:g}": (lambda dim, steps: lambda n, frame: p1_heat(dim, n, steps, 0, frame))(dim, steps)
        for name, dim in (("tri", 2), ("tet", 3)) for steps in (1, 10, 100, 1000)}

if __name__ == "__main__":
    if os.environ.get("METHODS"):
        keep = os.environ["METHODS"].split(",")
        for name in [m for m in units.METHODS if m not in keep]:
            del units.METHODS[name]
    units.CASES.update(HEAT)
    units.table(lambda A, b: {"A": (A, b)}, list(HEAT))
