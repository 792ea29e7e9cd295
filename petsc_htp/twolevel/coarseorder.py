"""A fill-reducing order of the coarse columns: METIS's nested dissection of the leaf graph (leaves joined where
A couples them), so the coarse operator comes out ordered and its LU takes the natural ordering.

On a bare 1024^2 DMDA matrix (106 974 coarse rows in 2x2 blocks) the LU then holds 13.4 against 18.0 million
values and factors in 648 against 1349 ms under PETSc's nested dissection (QMD: slower still), for 197 ms of
METIS once per pattern (with METIS's default ten refinement iterations per level, now one: see
:func:`nested_dissection`); 74 against 161 ms (QMD) at 27 000 rows for 42 ms of METIS, a loss below about 12 000
(:data:`~.sizing.COARSE_METIS_ROWS`; one column per piece: 40 000, :data:`~.sizing.COARSE_METIS_SCALAR_ROWS`).

On several ranks every rank orders its own leaves, those coupled to other ranks' last: in the gathered coarse
operator (PCREDUNDANT) the leaves inside each rank come in nested-dissection order and the ranks' interface
leaves form the top separator, so the natural ordering holds there too, and no graph is gathered.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .graphshape import hub_rows


def leaf_order(lay, rows) -> np.ndarray:
    """The order of one rank's leaves (position i holds leaf ``order[i]``): METIS's nested dissection of the
    leaves coupled only within the rank (an edge where A's ``rows`` couple two leaves: O's entries), but for hubs
    (:func:`.graphshape.hub_rows` of the leaf graph: a dense row's leaf), then the hubs, then the leaves coupled to
    other ranks' (one rank: a dense row is coupled within it; on several :func:`.sizing.metis_ordered` leaves the
    order to PETSc)."""
    leaf_of = lay.leaf[lay.iperm]
    col = rows.indices[lay.o_src].astype(np.int64) - lay.start
    local = (col >= 0) & (col < lay.n)
    row_leaf = leaf_of[lay.o_rows]
    K = lay.leaves.n_leaves
    interface = np.zeros(K, dtype=bool)
    interface[row_leaf[~local]] = True
    inner = np.flatnonzero(~interface)
    number = np.full(K, -1)
    number[inner] = np.arange(inner.size)
    r, c = number[row_leaf[local]], number[leaf_of[col[local]]]
    keep = (r >= 0) & (c >= 0) & (r != c)
    G = sp.csr_matrix((np.ones(int(keep.sum()), dtype=np.int32), (r[keep], c[keep])), shape=(inner.size,) * 2)
    G = (G + G.T).tocsr()
    hub = hub_rows(G.indptr, G.shape[0] ** 0.5)
    if hub.any():                   # a dense row's leaves go last, as a separator would: METIS took 130 against 60 ms
        rest = np.flatnonzero(~hub)
        order = np.concatenate([rest[nested_dissection(G[rest][:, rest].tocsr())], np.flatnonzero(hub)])
    else:
        order = nested_dissection(G)
    return np.concatenate([inner[order], np.flatnonzero(interface)])


def nested_dissection(G) -> np.ndarray:
    """METIS's fill-reducing order of ``G``'s vertices: position i holds vertex ``order[i]``."""
    import pymetis

    if G.shape[0] < 2:
        return np.arange(G.shape[0])
    # one refinement iteration per level, not ten: at 1024^2 (91 629 leaves) the LU holds 6.12 against 6.09 million
    # values, and METIS takes about 60 ms less
    order, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(G.indptr, G.indices), options=pymetis.Options(niter=1))
    return np.asarray(order, dtype=np.int64)
