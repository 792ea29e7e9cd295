"""The block size of an operator that does not state one: read off its nonzero pattern.

A program that assembles elasticity, or any system with several unknowns per node numbered node after node, into
a plain AIJ matrix (``MatLoad`` without ``-matload_block_size``, a scipy matrix handed to petsc4py) leaves the Mat's
block size 1, and the leaves then split nodes and the coarse space misses each component's constant: PyAMG's 2-D
elasticity at 45 000 rows took 243 CG iterations (659 ms) bare against 32 (178 ms) with the block size set, GAMG
164 and 17; 3-D trilinear elasticity at 27 783 rows 192 against 47. Such a pattern is blocked: the ``b`` rows of a
node together couple whole nodes (``b`` consecutive columns from a multiple of ``b``), whether or not the zero
couplings inside a block are stored (PyAMG's elasticity stores 28 % of its entries as explicit zeros; scipy's
arithmetic drops them). A scalar stencil's is not: a row couples its neighbour in the previous node alone.

The nodes of :data:`SAMPLE_ROWS` rows spread over each rank's rows are checked (1-3 ms on scalar matrices at 64k
rows, 3.3 ms on 2-D elasticity at 80 000 and 17 on 3-D at 45 000; all of 80 000 rows took 56-74 ms); where they
are blocked by ``b`` on every rank (:data:`CANDIDATES`; of several, the largest whose nodes hang together:
:func:`block_size`), the two-level method takes ``b`` as the block size: leaves of whole nodes and each component's
constant (:mod:`.nearnull`). A pattern blocked only where sampled (a few scalar rows among the nodes) gets nodes
too: any partition into nodes gives leaves and coarse vectors of a valid preconditioner, so a wrong guess costs
iterations, never the answer. A rank's rows may start or end inside a node (PETSc's split of 9 800 rows over 3
ranks): such a partial node is not checked. ``-htp_block_size`` overrides it all.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries

CANDIDATES = (6, 4, 3, 2)   # block sizes tried, the largest first (shells, 2-D plates, 3-D and 2-D elasticity)
SAMPLE_ROWS = 512           # rows whose nodes are checked
FIRST_ROWS = 64             # ... of them first (a scalar pattern fails at nearly every node)
SHIFTED_MAX = 0.5           # share of nodes shifted by one row that may pass as well (elasticity: none)
MIN_NODES = 8               # nodes checked over all ranks below which no block size is taken (a few rows tell nothing)
MAX_BLOCK = 64              # the largest -htp_block_size


def _distinct(values) -> np.ndarray:
    """The distinct ``values``, sorted (a sort and a mask: numpy's hashing unique took 3 ms on 20 000 values)."""
    values = np.sort(values)
    return values[np.r_[True, values[1:] != values[:-1]]] if values.size else values


def _nodes(n, start, b, rows, shift=0) -> tuple:
    """(first local row of the first whole node, the whole nodes of local ``rows`` numbered from it) of ``n`` local
    rows whose first is global row ``start``, in nodes of ``b`` rows by global row + ``shift``."""
    lo = (-(start + shift)) % b
    nodes = _distinct((rows[rows >= lo] - lo) // b)
    return lo, nodes[lo + (nodes + 1) * b <= n]


def passing(indptr, indices, start, b, rows, shift=0) -> np.ndarray:
    """For each whole node of ``rows`` (local row numbers; nodes of ``b`` rows by global row + ``shift``, the first
    local row global row ``start``, partial nodes at either end skipped) of the CSR rows ``indptr``/``indices``
    (global columns), whether it couples whole column nodes (columns + ``shift``): whether the union of its rows'
    columns is a union of nodes of ``b`` columns (a block's zeros need not be stored)."""
    lo, nodes = _nodes(indptr.size - 1, start, b, rows, shift)
    ok = np.ones(nodes.size, dtype=bool)
    where, owner = row_entries(indptr, (lo + nodes[:, None] * b + np.arange(b)).ravel())
    if where.size == 0:
        return ok
    cols = indices[where].astype(np.int64) + shift
    width = int(cols.max()) + b                                       # keys below 2^63 up to 4e15 columns
    key = _distinct((owner // b) * np.int64(width) + cols)           # each node's columns, sorted, once
    node, cols = np.divmod(key, width)
    runs = np.flatnonzero(np.r_[True, (node[1:] != node[:-1]) | (cols[1:] // b != cols[:-1] // b)])
    ok[node[runs[np.diff(np.r_[runs, key.size]) != b]]] = False     # a run of one column node short of b
    return ok


def joined(indptr, indices, start, b, rows) -> int:
    """How many whole nodes of ``rows`` (as :func:`passing` takes them) have a connected diagonal block: its ``b``
    rows joined by their entries inside the node (a 6-row node of three uncoupled 2 x 2 blocks is not)."""
    lo, nodes = _nodes(indptr.size - 1, start, b, rows)
    first = lo + nodes * b                                            # each node's first local row
    where, owner = row_entries(indptr, (first[:, None] + np.arange(b)).ravel())
    node, r = owner // b, owner % b
    c = indices[where].astype(np.int64) - (start + first[node])      # the column within the node
    inside = (c >= 0) & (c < b)
    reach = np.zeros((nodes.size, b, b), dtype=bool)
    reach[node[inside], r[inside], c[inside]] = True
    reach |= reach.transpose(0, 2, 1) | np.eye(b, dtype=bool)
    for _ in range(3):                                               # paths of up to 8 >= b steps
        reach = np.einsum("kij,kjl->kil", reach.astype(np.int8), reach.astype(np.int8)) > 0
    return int(np.count_nonzero(reach[:, 0, :].all(axis=1)))


def detect(indptr, indices, start) -> tuple:
    """Per :data:`CANDIDATES`, how many nodes of :data:`SAMPLE_ROWS` rows spread over this rank's rows were found
    blocked by it (:func:`passing`; -1: not blocked), :data:`FIRST_ROWS` of them first (a scalar pattern fails
    there), then how many of those have a connected diagonal block (:func:`joined`). A scalar stencil whose reach
    is a multiple of ``b`` (a 13-point biharmonic stencil's 2 and 2 nx, a diagonal matrix) also couples whole
    nodes, but as well with its nodes shifted by one row, which a system's nodes do not: where more than
    :data:`SHIFTED_MAX` of the shifted nodes pass too, not blocked."""
    n = indptr.size - 1
    few, many = (np.arange(0, n, max(1, n // k)) for k in (FIRST_ROWS, SAMPLE_ROWS))
    counts = tuple(_blocked(indptr, indices, start, b, few, many) for b in CANDIDATES)
    joins = tuple(joined(indptr, indices, start, b, many) if count >= 0 else 0
                  for b, count in zip(CANDIDATES, counts))
    return counts, joins


def _blocked(indptr, indices, start, b, few, many) -> int:
    """How many nodes of the rows ``many`` :func:`passing` found blocked by ``b``, after those of ``few``, and not
    also shifted by one row (more than :data:`SHIFTED_MAX` of them); -1 where not blocked."""
    if not passing(indptr, indices, start, b, few).all():
        return -1
    ok = passing(indptr, indices, start, b, many)
    if not ok.all():
        return -1
    shifted = passing(indptr, indices, start, b, many, shift=1)
    return -1 if shifted.size and shifted.mean() > SHIFTED_MAX else ok.size


def block_size(mat, rows, coll, option=0) -> tuple:
    """(block size, where it comes from) for the two-level method: ``option`` where set (1 to :data:`MAX_BLOCK`),
    else the Mat's where above 1, else of :data:`CANDIDATES` that block every rank's sampled rows, at least
    :data:`MIN_NODES` nodes checked in all (collective), the largest whose nodes' diagonal blocks are mostly
    connected, or failing that the smallest (nodes of a larger candidate made of uncoupled smaller ones, as in a
    block-diagonal matrix of 2 x 2 blocks, which nodes of 2, 4 and 6 all block), else 1."""
    if option > MAX_BLOCK:
        raise ValueError(f"-htp_block_size {option} is more unknowns per node than {MAX_BLOCK}")
    if option >= 1:
        return option, "from -htp_block_size"
    if mat.getBlockSize() > 1:
        return mat.getBlockSize(), "the Mat's"
    start = mat.getOwnershipRange()[0]
    counts, joins = (np.array(v, dtype=np.int64) for v in detect(rows.indptr, rows.indices, start))
    k = len(CANDIDATES)
    total = coll.sum_array(np.concatenate([counts < 0, np.maximum(counts, 0), joins]).astype(np.int64))
    found = [(b, joined / checked) for b, failed, checked, joined
             in zip(CANDIDATES, total[:k], total[k:2 * k], total[2 * k:]) if not failed and checked >= MIN_NODES]
    for b, share in found:
        if share >= 0.5:
            return b, "found in the pattern"
    return (found[-1][0], "found in the pattern") if found else (1, "")
