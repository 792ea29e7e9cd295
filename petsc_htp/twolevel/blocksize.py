"""The block size of an operator that does not state one: read off its nonzero pattern.

A program that assembles elasticity, or any system with several unknowns per node numbered node after node, into
a plain AIJ matrix (``MatLoad`` without ``-matload_block_size``, a scipy matrix handed to petsc4py) leaves the Mat's
block size 1, and the leaves then split nodes and the coarse space misses each component's constant: PyAMG's 2-D
elasticity at 45 000 rows took 243 CG iterations (659 ms) bare against 32 (178 ms) with the block size set, GAMG
164 and 17; 3-D trilinear elasticity at 27 783 rows 192 against 47. Such a pattern is blocked: the ``b`` rows of a
node hold the same columns, and those come as whole nodes (``b`` consecutive columns from a multiple of ``b``). A
scalar stencil's is not (a row's neighbours differ from the next row's), so where the pattern is exactly blocked by
``b`` on every rank (:data:`CANDIDATES`: 6, 4, 3 or 2, the largest such; a rank's rows may start or end inside a
node, as PETSc's split of 9 800 rows over 3 ranks does) the two-level method takes it as the block size: leaves of
whole nodes and each component's constant (:mod:`.nearnull`). ``-htp_block_size`` overrides it.
"""
from __future__ import annotations

import numpy as np

from .csr import row_entries

CANDIDATES = (6, 4, 3, 2)   # block sizes tried, the largest first (shells, 2-D plates, 3-D and 2-D elasticity)
SAMPLE_ROWS = 4096      # rows checked first (a scalar pattern fails there), before all of them


def blocked(indptr, indices, start, b, rows=None) -> bool:
    """Whether the CSR rows ``indptr``/``indices`` (global columns, sorted; the first row is global row ``start``)
    come in nodes of ``b`` rows (global row // b; a rank's first and last node may be partial) whose rows hold the
    same columns, which are whole nodes; ``rows``: check only those (local numbers)."""
    n = indptr.size - 1
    if n == 0:
        return True
    lengths = np.diff(indptr)
    rows = np.arange(n) if rows is None else rows
    mate = np.maximum((start + rows) // b * b, start) - start        # the node's first row on this rank
    if np.any(lengths[rows] != lengths[mate]) or np.any(lengths[rows] % b):
        return False
    where, owner = row_entries(indptr, rows)
    pos = where - indptr[rows[owner]]                                 # the entry's place in its row
    same = indptr[mate[owner]] + pos                                  # the same place in the node's first row
    lead = indices[same - pos % b].astype(np.int64)                   # the first column of its column node
    return bool(np.array_equal(indices[where], indices[same]) and np.all(lead % b == 0)
                and np.all(indices[same] == lead + pos % b))


def detect(indptr, indices, start) -> tuple:
    """Flags (one per :data:`CANDIDATES`): whether this rank's rows are blocked by each, a sample of rows first."""
    flags = []
    n = indptr.size - 1
    sample = np.arange(0, n, max(1, n // SAMPLE_ROWS))
    for b in CANDIDATES:
        flags.append(blocked(indptr, indices, start, b, sample) and blocked(indptr, indices, start, b))
    return tuple(flags)


def block_size(mat, rows, coll, option=0) -> tuple:
    """(block size, where it comes from) for the two-level method: ``option`` where set (>= 1), else the Mat's
    where above 1, else the largest of :data:`CANDIDATES` that blocks every rank's rows (collective), else 1."""
    if option >= 1:
        return option, "from -htp_block_size"
    if mat.getBlockSize() > 1:
        return mat.getBlockSize(), "the Mat's"
    flags = np.array(detect(rows.indptr, rows.indices, mat.getOwnershipRange()[0]), dtype=np.int64)
    agreed = coll.min_array(flags)
    for b, ok in zip(CANDIDATES, agreed):
        if ok:
            return b, "found in the pattern"
    return 1, ""
