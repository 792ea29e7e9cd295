"""Shifted rows: one backward-Euler step of the heat equation, M + dt K with P1 elements on unstructured triangles
and tetrahedra (petsc_htp.scenes.meshes.p1_heat, dt = s h^2 for s = 1, 10, 100, 1000). HTPPC as it comes (ICC(0) of
the whole matrix, of each rank's block on several, where the median sampled row sums to 0.0025 of its diagonal and
unshifted ICC(0)'s trial on each rank's whole block, up to 2^21 stored entries, confirms;
petsc_htp.twolevel.incomplete), HTPPC's two-level method (-htp_direct_max 0: what HTPPC did on these matrices
before), ICC(0) alone (PCBJACOBI's, one block per rank) and GAMG (PETSc's defaults): the methods and table of
results/rotated-20261127/run.py, one solve each from a fresh Mat and KSP after a warm-up solve, CG to rtol 1e-8 in
the unpreconditioned norm: setup + solve ms (iterations) [true relative residual].

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 [METHODS=htppc,icc] [mpiexec -n 2] \
        python results/shifted-20261127/run.py [N] [case ...]
"""
import importlib.util
from pathlib import Path

from petsc_htp.scenes.meshes import p1_heat

spec = importlib.util.spec_from_file_location(
    "rotated_run", Path(__file__).resolve().parent.parent / "rotated-20261127" / "run.py")
rotated = importlib.util.module_from_spec(spec)       # its four methods, its table
spec.loader.exec_module(rotated)
HEAT = {f"heat_{name}_{steps:g}": (lambda dim, steps: lambda n, frame: p1_heat(dim, n, steps, 0, frame))(dim, steps)
        for name, dim in (("tri", 2), ("tet", 3)) for steps in (1, 10, 100, 1000)}

if __name__ == "__main__":
    rotated.units.CASES.update(HEAT)
    rotated.main(list(HEAT))
