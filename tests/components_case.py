"""Run under mpiexec (any number of ranks): the connected components HTPPC's two-level analysis finds on several ranks
(each rank's own first, then those joined by couplings between ranks) against scipy's on the whole matrix: chains
within a rank and across a rank boundary, a coupling between the first and the last rank alone, decoupled rows;
prints 'components ok'."""
import sys

import petsc4py

petsc4py.init(sys.argv)
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from scipy.sparse.csgraph import connected_components  # noqa: E402

import petsc_htp  # noqa: E402

N = 180


def graph() -> sp.csr_matrix:
    """The whole matrix, the same on every rank: graph Laplacian + 0.1 I of chains, a far coupling, lone rows."""
    edges = [(i, i + 1) for i in range(40, 80)]                  # across the first rank boundary (3 ranks: 60)
    edges += [(i, i + 1) for i in range(100, 110)]               # within the second rank
    edges += [(i, i + 1) for i in range(0, 20)] + [(20, 170)]    # first rank to the last rank directly
    edges += [(i, i + 1) for i in range(150, 175) if i != 160]   # two chains on the last rank, one joined above
    rows, cols = np.array(edges).T
    adj = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(N, N))
    adj = (adj + adj.T).tocsr()
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    return sp.csr_matrix(lap + 0.1 * sp.identity(N))


def main():
    comm = PETSc.COMM_WORLD
    A = graph()
    mat = PETSc.Mat().createAIJ((N, N), comm=comm)
    start, end = mat.getOwnershipRange()
    local = A[start:end]
    mat.setPreallocationCSR((local.indptr, local.indices))
    mat.setValuesCSR(local.indptr, local.indices, local.data)
    mat.assemble()
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(mat)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-10)
    pc = ksp.getPC()
    pc.setType("python")
    PETSc.Options().setValue("htp_direct_max", 0)       # the two-level analysis, not the small matrix's factor
    ctx = petsc_htp.HTPPC()
    pc.setPythonContext(ctx)
    b, x = mat.createVecs()
    b.set(1.0)
    ksp.solve(b, x)
    assert ksp.getConvergedReason() > 0, ksp.getConvergedReason()
    st = ctx.setup.st
    n_ref, ref = connected_components(A, directed=False)
    ours = np.concatenate(comm.tompi4py().allgather(st.comp_of_row))
    pairs = np.unique(np.stack([ours, ref], 1), axis=0)
    assert st.n_comp == n_ref and len(pairs) == n_ref, (st.n_comp, n_ref, len(pairs))       # the same partition
    piece_rows = st.lay.pieces.label[st.lay.iperm] + st.piece_offset
    assert np.array_equal(st.comp_of_piece[piece_rows], st.comp_of_row)
    PETSc.Sys.Print(f"components ok on {comm.getSize()} ranks ({n_ref} components)")


if __name__ == "__main__":
    main()
