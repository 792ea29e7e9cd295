"""Write one of run.py's graphs (ba: Barabasi-Albert; mixed: both signs) of N rows and a random right-hand side to a
PETSc binary file, for examples/matrix_file.py on several ranks (ranks.sh).

    python results/expander-20261126/write.py N ba|mixed FILE
"""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(["write"])
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import barabasi_albert, mixed_signs  # noqa: E402

n = int(sys.argv[1])
A = barabasi_albert(n, 3) if sys.argv[2] == "ba" else mixed_signs(n)
mat = PETSc.Mat().createAIJ(A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data),
                            comm=PETSc.COMM_SELF)
rhs = mat.createVecLeft()
rhs.setArray(np.random.default_rng(1).standard_normal(n))
viewer = PETSc.Viewer().createBinary(sys.argv[3], "w", comm=PETSc.COMM_SELF)
mat.view(viewer)
rhs.view(viewer)
viewer.destroy()
