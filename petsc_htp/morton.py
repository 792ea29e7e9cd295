"""Morton (Z-order) codes for 2-D and 3-D points."""
import numpy as np

MAX_BITS = {2: 32, 3: 21}          # bits per axis that fit a 64-bit code
_SPREAD_STEPS = {
    2: ((16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF), (4, 0x0F0F0F0F0F0F0F0F), (2, 0x3333333333333333),
        (1, 0x5555555555555555)),
    3: ((32, 0x001F00000000FFFF), (16, 0x001F0000FF0000FF), (8, 0x100F00F00F00F00F), (4, 0x10C30C30C30C30C3),
        (2, 0x1249249249249249)),
}


def _as_index_array(values, name, bits):
    """Return ``values`` as a uint64 array of integers in ``[0, 2**bits)``."""
    arr = np.asarray(values)
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must be an integer array, got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() >= 2**bits):
        raise ValueError(f"{name} must lie in [0, 2**{bits})")
    return arr.astype(np.uint64)


def _spread_bits(v, dim):
    """Move bit k of each uint64 entry of ``v`` to bit ``dim * k``."""
    for shift, mask in _SPREAD_STEPS[dim]:
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_code(ix, iy, iz=None):
    """Interleave the bits of two or three non-negative integer arrays.

    Parameters
    ----------
    ix, iy : array_like of int
        Non-negative integers below ``2**32`` (``2**21`` with ``iz``); broadcast against each other.
    iz : array_like of int, optional
        The third axis (3-D codes).

    Returns
    -------
    numpy.ndarray of uint64
        Codes with bit k of ``ix`` at bit ``d k``, of ``iy`` at ``d k + 1`` and of ``iz`` at ``d k + 2``
        (``d`` = 2 or 3).
    """
    axes = [(ix, "ix"), (iy, "iy")] + ([] if iz is None else [(iz, "iz")])
    dim = len(axes)
    code = np.uint64(0)
    for k, (values, name) in enumerate(axes):
        code = code | (_spread_bits(_as_index_array(values, name, MAX_BITS[dim]), dim) << np.uint64(k))
    return code


def _lattice_indices(x, bits):
    """Integer indices ``(x - min) / spacing`` when ``x`` lies on a uniform lattice, else None.

    The spacing comes from a strided sample's distinct values and is checked on every point (all of
    them give it when the sample's spacing is a multiple of the true one).
    """
    for u in (np.unique(x[:: max(1, x.size // 4096)]), None):
        u = np.unique(x) if u is None else u
        if u.size < 2:
            continue
        k = (x - x.min()) / np.diff(u).min()
        q = np.rint(k)
        if np.abs(k - q).max() <= 1e-6:
            return q.astype(np.int64) if q.max() < 2**bits else None
    return np.zeros(x.size, dtype=np.int64) if np.all(x == x[0]) else None


def quantized_morton_codes(coords, bits=16):
    """Morton codes of points quantised to integers.

    Points on a uniform lattice (cell centres of a grid, with or without
    holes) get the codes of their integer lattice indices, so a grid's
    cells come out in the same order as :func:`morton_code` of its cell
    indices; other points are mapped onto ``[0, 2**bits)`` over their
    bounding box, each axis separately.

    Parameters
    ----------
    coords : array_like, shape (N, 2) or (N, 3)
        Finite point coordinates.
    bits : int
        Quantisation bits per axis, in ``[1, 32]`` (``[1, 21]`` in 3-D).

    Returns
    -------
    numpy.ndarray of uint64, shape (N,)
    """
    pts = np.asarray(coords, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in MAX_BITS:
        raise ValueError(f"coords must have shape (N, 2) or (N, 3), got {pts.shape}")
    dim = pts.shape[1]
    if not np.all(np.isfinite(pts)):
        raise ValueError("coords must be finite")
    if not 1 <= bits <= MAX_BITS[dim]:
        raise ValueError(f"bits must lie in [1, {MAX_BITS[dim]}] in {dim}-D, got {bits}")
    if pts.shape[0] == 0:
        return np.zeros(0, dtype=np.uint64)
    lattice = [_lattice_indices(pts[:, a], bits) for a in range(dim)]
    if all(q is not None for q in lattice):
        return morton_code(*lattice)
    lo = pts.min(axis=0)
    span = pts.max(axis=0) - lo
    span[span == 0] = 1.0  # a flat axis quantises to 0
    q = np.minimum(np.floor((pts - lo) * (2.0**bits / span)), 2**bits - 1)
    return morton_code(*q.astype(np.int64).T)


def morton_permutation(coords, bits=16):
    """Stable ordering of 2-D or 3-D points along the Morton curve.

    Parameters
    ----------
    coords : array_like, shape (N, 2) or (N, 3)
        Finite point coordinates.
    bits : int
        Quantisation bits per axis (see :func:`quantized_morton_codes`).

    Returns
    -------
    numpy.ndarray of int64, shape (N,)
        Indices that sort the points by Morton code, ties kept in input order.
    """
    codes = quantized_morton_codes(coords, bits)
    return np.argsort(codes, kind="stable").astype(np.int64)
