"""A fresh process's import of petsc_htp.pc (after petsc4py, numpy and scipy.sparse), python -X importtime's cumulative
microseconds, the least of 5 processes, for the code at each ROOT given (2026-11-28, this 2-core AMD EPYC). From the
repository root:
    python results/renew-20261128/imports.py ROOT [ROOT ...]
"""
import subprocess
import sys

CODE = "import petsc4py; petsc4py.init(); from petsc4py import PETSc; import numpy, scipy.sparse; import petsc_htp.pc"

for root in sys.argv[1:]:
    times, loaded = [], ""
    for _ in range(5):
        run = subprocess.run([sys.executable, "-X", "importtime", "-c", CODE + "; import sys; print('scipy.sparse.csgraph' "
                              "in sys.modules)"], cwd=root, capture_output=True, text=True, check=True)
        line = [x for x in run.stderr.splitlines() if x.rstrip().endswith("| petsc_htp.pc")][0]
        times.append(int(line.split("|")[1]) / 1000)
        loaded = run.stdout.strip()
    print(f"{root}: import petsc_htp.pc {min(times):.1f} ms (least of 5); scipy.sparse.csgraph loaded: {loaded}")
