"""Leaf rows by degree on small matrices numbered at random (N about 16k, below leaves.A_ORDER_SPAN, where only
leaves.SCATTERED finds the numbering scattered): HTPPC's two-level method as it comes against the same with A's
order kept within the leaves (SCATTERED raised past any span), in turn in one process, 5 rounds; medians of the
last 4 of setup and solve ms, iterations and the leaf solver's stored values.

    OMP_NUM_THREADS=1 python results/numbering-20261126/scattered.py > results/numbering-20261126/scattered.txt
"""
import subprocess
import sys
import time
from pathlib import Path

import petsc4py

petsc4py.init(["scattered"])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from petsc_htp.bench.foreigncases import CASES  # noqa: E402
from petsc_htp.twolevel import leaves  # noqa: E402
from timed import fresh_solve  # noqa: E402

CONFIGS = {"by degree": leaves.SCATTERED, "A's order": 10.0}


PETSc.Options().setValue("htp_direct_max", 0)                  # the two-level method at this size
commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
print(f"# {time.strftime('%Y-%m-%d')}, commit {commit.stdout.strip()}")
for case in ("free_surface", "fem_tri", "fem_tet"):
    A, b = CASES[case](16384, 0)
    if case == "free_surface":                                   # grid order: permuted at random here
        p = np.random.default_rng(0).permutation(A.shape[0])
        A, b = sp.csr_matrix(A[p][:, p]), b[p]
        A.sort_indices()
    mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType),
                                              A.data), comm=PETSc.COMM_SELF)
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    rows = {c: [] for c in CONFIGS}
    for _ in range(5):
        for label, share in CONFIGS.items():
            leaves.SCATTERED = share
            rows[label].append(fresh_solve(mat, b))
    for label, r in rows.items():
        setup, solve = np.median(np.array([x[:2] for x in r[1:]]), axis=0)
        print(f"{case} N={A.shape[0]} {label}: setup {setup:.1f} solve {solve:.1f} ms, {r[-1][2]} iterations, "
              f"leaf solver {r[-1][3]} values", flush=True)
