"""mpiexec -n 2 python tests/sbaij_case.py [raw]: an MPISBAIJ matrix of 3x3 blocks set row by row from its upper triangle
(MAT_IGNORE_LOWER_TRIANGULAR, block preallocation), as an assembly loop writes it; prints the largest
|copy x - M x| of HTPPC's AIJ copy (PETSc's own conversion with 'raw')."""
import sys
from pathlib import Path
import petsc4py
petsc4py.init(sys.argv[:1])
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc
from petsc_htp.petscmat import aij_operator

comm, bs, side = PETSc.COMM_WORLD, 3, 6
T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (side, side))
grid = sp.kronsum(sp.kronsum(T, T), T)
node = np.array([[4.0, 1.0, 0.5], [1.0, 4.0, 1.0], [0.5, 1.0, 4.0]])
A = (sp.kron(grid, node) + sp.kron(sp.identity(side ** 3), node)).tocsr()
N = A.shape[0]
M = PETSc.Mat().create(comm)
M.setSizes(((None, N), (None, N)), bsize=bs)
M.setType("sbaij")
M.setOption(PETSc.Mat.Option.IGNORE_LOWER_TRIANGULAR, True)
lo, hi = M.getOwnershipRange()
upper = sp.triu(A, format="csr")[lo:hi]
blocks = sp.csr_matrix((np.ones(upper.nnz), upper.indices // bs, upper.indptr), shape=(hi - lo, N // bs)).tocsr()
count = np.diff(sp.csr_matrix(blocks[::bs] + blocks[1::bs] + blocks[2::bs]).indptr).astype(PETSc.IntType)
M.setPreallocationNNZ((count, count))
for i in range(hi - lo):
    s, e = upper.indptr[i], upper.indptr[i + 1]
    M.setValues([lo + i], upper.indices[s:e], upper.data[s:e])
M.assemble()
C = M.convert("mpiaij" if comm.getSize() > 1 else "seqaij", out=PETSc.Mat()) if "raw" in sys.argv else aij_operator(M)
x = M.createVecRight()
x.setArray(np.random.default_rng(0).standard_normal(hi - lo))
y, z = M.createVecLeft(), M.createVecLeft()
M.mult(x, y)
C.mult(x, z)
z.axpy(-1.0, y)
PETSc.Sys.Print(f"difference {z.norm(PETSc.NormType.INFINITY):.3e} type {C.getType()}")
