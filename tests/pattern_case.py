"""Run under mpiexec: a Pattern (O's and W's matrix) against PETSc's COO assembly of the same entries on every rank,
frame after frame, through a product and a matrix-vector product; prints 'pattern ok'."""
import sys

import petsc4py

petsc4py.init(sys.argv)
import numpy as np  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp.twolevel.operators import Pattern  # noqa: E402


def coo(comm, rows, cols, shape, local):
    """PETSc's COO assembly of the same entries (the reference)."""
    mat = PETSc.Mat().create(comm=comm)
    mat.setSizes(((local[0], shape[0]), (local[1], shape[1])))
    mat.setType(PETSc.Mat.Type.AIJ)
    mat.setPreallocationCOO(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType))
    return mat


def main():
    comm = PETSc.COMM_WORLD
    rank, size = comm.getRank(), comm.getSize()
    rng = np.random.default_rng(7 + rank)
    local = (5 + rank, 4 + 2 * rank)                       # rows and columns differ per rank
    shape = (comm.tompi4py().allreduce(local[0]), comm.tompi4py().allreduce(local[1]))
    first = comm.tompi4py().exscan(local[0]) or 0
    dense = rng.random((local[0], shape[1])) < 0.35
    dense[0] = False                                       # an empty row
    if rank == 1:
        dense[:, :] = False                                # a rank with no entries off its diagonal block
        dense[1, 5] = dense[3, 6] = True
    rows, cols = np.nonzero(dense)
    shuffle = rng.permutation(rows.size)
    rows, cols = rows[shuffle] + first, cols[shuffle]
    ours = Pattern(comm, rows, cols, shape, local, col_block=1)
    ref = coo(comm, rows, cols, shape, local)
    x = ref.createVecRight()
    x.setRandom()
    for _ in range(2):
        values = rng.standard_normal(rows.size)
        ours.set(values)
        ref.setValuesCOO(values)
        y, z = ours.mat.createVecLeft(), ref.createVecLeft()
        ours.mat.mult(x, y)
        ref.mult(x, z)
        assert np.allclose(y.getArray(), z.getArray(), rtol=0, atol=1e-14), (y.getArray(), z.getArray())
        prod, want = ours.mat.transposeMatMult(ours.mat), ref.transposeMatMult(ref)
        prod.axpy(-1.0, want)
        assert prod.norm() < 1e-12, prod.norm()
        for m in (y, z, prod, want):
            m.destroy()
    try:
        Pattern(comm, rows + local[0], cols, shape, local)
    except ValueError as err:
        assert "this rank's rows" in str(err)
    else:
        raise AssertionError("rows of another rank were taken")
    PETSc.Sys.Print(f"pattern ok on {size} ranks")


main()
