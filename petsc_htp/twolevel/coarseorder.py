"""A fill-reducing order of the coarse columns: METIS's nested dissection of the leaf graph (leaves joined where
A couples them), so the coarse operator comes out ordered and its LU takes the natural ordering.

On a bare 1024^2 DMDA matrix (106 974 coarse rows in 2x2 blocks) the LU then holds 13.4 against 18.0 million
values and factors in 648 against 1349 ms under PETSc's nested dissection (QMD: slower still), for 197 ms of
METIS once per pattern; 74 against 161 ms (QMD) at 27 000 rows for 42 ms of METIS, a loss below about 12 000
(:data:`~.sizing.COARSE_METIS_ROWS`). Only on one rank: on several, every rank's columns are its own block.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def leaf_graph(lay, rows) -> sp.csr_matrix:
    """The symmetric graph of the leaves of one rank's ``lay``, an edge where A's ``rows`` couple two leaves
    (O's entries), without self loops."""
    leaf_of = lay.leaf[lay.iperm]
    r, c = leaf_of[lay.o_rows], leaf_of[rows.indices[lay.o_src] - lay.start]
    K = lay.leaves.n_leaves
    G = sp.csr_matrix((np.ones(r.size, dtype=np.int8), (r, c)), shape=(K, K))
    G = (G + G.T).tocsr()
    G.setdiag(0)
    G.eliminate_zeros()
    return G


def nested_dissection(G) -> np.ndarray:
    """METIS's fill-reducing order of ``G``'s vertices: position i holds vertex ``order[i]``."""
    import pymetis

    if G.shape[0] < 2:
        return np.arange(G.shape[0])
    order, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(G.indptr, G.indices))
    return np.asarray(order, dtype=np.int64)
