"""The operator's near null space beyond the constant, as coarse vectors every leaf takes as they are.

PETSc programs say what their operator's smooth modes are as GAMG reads them: a near null space attached to the
Mat (``MatSetNearNullSpace``, such as the rigid-body modes of ``MatNullSpaceCreateRigidBody``), or else a block
size, whose components each have their own constant (the Mat's, or one its pattern shows: :mod:`.blocksize`).
The two-level method keeps each piece's constant and adds these vectors, restricted to every leaf and made
orthonormal there (:func:`.coarsespace.basis`), so that an elasticity operator's coarse space holds its translations
and rotations. A scalar matrix with neither has
none: the piece constants are its near null space.
"""
from __future__ import annotations

import numpy as np


def vectors(mat, bs):
    """(n, f) array of ``mat``'s near null vectors on this rank (A's local rows), or None: the attached near null
    space's vectors, else with a block size ``bs`` > 1 (:mod:`.blocksize`) the indicators of its first bs - 1
    components (the last one follows from the constant)."""
    near = mat.getNearNullSpace()
    if near.handle:
        vecs = near.getVecs()
        return np.stack([v.getArray(readonly=True) for v in vecs], axis=1) if vecs else None
    if bs <= 1:
        return None
    start, end = mat.getOwnershipRange()
    return (np.arange(start, end)[:, None] % bs == np.arange(bs - 1)[None, :]).astype(np.float64)


def count(mat, bs) -> int:
    """How many near null vectors :func:`vectors` gives for ``mat`` and ``bs`` (the columns they take per leaf);
    collective only in that every rank answers alike."""
    near = mat.getNearNullSpace()
    if near.handle:
        return len(near.getVecs())
    return max(bs - 1, 0)


def spans_constant(mat, tol=1e-8) -> bool:
    """Whether ``mat``'s attached near null vectors span the constant on this rank's rows (least squares residual at
    most ``tol`` times the constant's norm): the rigid-body modes do, their translations summing to it."""
    Z = vectors(mat, 1) if attached(mat) else None
    if Z is None or Z.shape[0] == 0:
        return False
    ones = np.ones(Z.shape[0])
    coef = np.linalg.lstsq(Z, ones, rcond=None)[0]
    return bool(np.linalg.norm(Z @ coef - ones) <= tol * np.sqrt(Z.shape[0]))


def attached(mat) -> bool:
    """Whether ``mat`` carries a near null space of its own (not only a block size)."""
    return bool(mat.getNearNullSpace().handle)


def describe(mat, bs, source) -> str:
    """Where :func:`vectors` takes its vectors from (``source``: where the block size ``bs`` came from), for
    ``-ksp_view``."""
    near = mat.getNearNullSpace()
    if near.handle:
        return "the Mat's near null space"
    return f"block size {bs}, {source}: each component's constant"
