"""The two-level coarse vectors of every leaf, from one sparse solve with the leaves' Neumann matrices.

Each leaf gets, in this order, q vectors from one block inverse-iteration step of its local Neumann
matrix S (the leaf block with every coupling out of the leaf folded into the diagonal, slightly
shifted) from smooth seeds, made orthogonal to the constants of the leaf's pieces
(:mod:`petsc_htp.twolevel.nullspace`) and orthonormal; with ``extra`` > 0, that many more seeds through the
same step, made orthogonal to all of those and kept where their Ritz value is at most ``tol`` times
the leaf's mean diagonal; then the normalised constant of each of its pieces. Vectors that come out
linearly dependent are left zero, as are kept-out extras: a zero coarse vector is an unused column.
One step from smooth seeds gives approximate low eigenvectors, which take fewer CG iterations here
than converged ones.

Rows are in the leaves' order (:class:`~petsc_htp.twolevel.leaflayout.LeafLayout`); the batched per-leaf work
runs on the padded (K, Lmax, q) layout, in numpy (the torch back-end converts). ``solve`` applies S^-1 to an
(n, q) array, so the factor can be PETSc's (:mod:`petsc_htp.twolevel.space`) or any other.
"""
from __future__ import annotations

import numpy as np

DEPENDENT = 1e-6       # a direction with a singular value below this times the leaf's largest is dropped
NEUMANN_SHIFT = 1e-4   # S's shift, times the leaf's mean |diagonal| (its constants are exact coarse vectors)


def seeds(leaf, offsets, sizes, first, count) -> np.ndarray:
    """Smooth start vectors cos(pi j (i + 1/2) / n_k), j = first .. first + count - 1, as an (n, count) array.

    ``i`` is a row's position in its leaf and ``n_k`` the leaf's size (rows in the leaves' order).
    """
    i = np.arange(leaf.size) - offsets[leaf] + 0.5
    j = np.arange(first, first + count)
    return np.asfortranarray(np.cos(np.pi * i[:, None] * j[None, :] / sizes[leaf][:, None]))


def neumann_diagonal(diag, outside, leaf, sizes) -> np.ndarray:
    """S's diagonal: A's diagonal plus the sum of each row's couplings out of its leaf (``outside``), shifted."""
    folded = diag + outside
    mean = np.bincount(leaf, np.abs(folded), minlength=sizes.size) / sizes
    return folded + NEUMANN_SHIFT * mean[leaf]


def lift(diag):
    """What to add to the coarse operator's diagonal ``diag``: its largest magnitude where it is zero (an unused,
    all-zero coarse vector), nothing elsewhere; same type as ``diag`` (numpy or torch)."""
    top = abs(diag).max()
    top = float(top.detach() if hasattr(top, "detach") else top)
    scale = top if top > 0 else 1.0
    return (diag == 0) * scale


def piece_constants(lay, index=None) -> np.ndarray:
    """(K, Lmax, c): every piece's normalised constant in column ``index`` (default: its index within the leaf;
    a negative index: the piece has no column), c the most columns a leaf uses."""
    K, L = lay.shape
    pc = lay.pieces
    index = pc.index if index is None else index[pc.label]
    used = index >= 0
    P = np.zeros((K * L, int(index.max(initial=-1)) + 1))
    P[lay.pos[used], index[used]] = 1.0 / np.sqrt(pc.size[pc.label[used]])
    return P.reshape(K, L, -1)


def flat(y, leaf, pieces, weights=None) -> tuple:
    """The one eig vector of every leaf (q = 1, no extras) without the padded layout, as :func:`basis` makes it:
    ``y`` (n,) in the leaves' order made orthogonal to the constants of the leaf's pieces (its mean on each piece
    taken out; a piece of one row, such as a decoupled row, becomes zero), or to the pieces' ``weights`` (n,) where
    they replace the constants (:mod:`.scaling`), then normalised per leaf twice (the second pass removes the
    first's rounding); a leaf where less than :data:`DEPENDENT` of its norm is left gets none.

    Returns (the vector, whether each leaf kept one). A failed factor's infinite values pass through quietly: the
    setup's checks name the failure (a coarse space that is not finite)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return _flat(y, leaf, pieces, weights)


def _flat(y, leaf, pieces, weights) -> tuple:
    """:func:`flat`'s arithmetic."""
    scale = np.sqrt(np.bincount(leaf, y * y, minlength=pieces.count.size))
    w = 1.0 if weights is None else weights
    w2 = pieces.size if weights is None else np.bincount(pieces.label, w * w, minlength=pieces.size.size)
    y = y - (np.bincount(pieces.label, y * w, minlength=pieces.size.size) / np.maximum(w2, 1e-300))[pieces.label] * w
    ok = np.ones(scale.size, dtype=bool)
    floor = DEPENDENT * scale
    for _ in range(2):
        norm = np.sqrt(np.bincount(leaf, y * y, minlength=scale.size))
        ok &= norm > floor
        y = np.where(ok[leaf], y / np.where(ok, norm, 1.0)[leaf], 0.0)
        floor = np.full(scale.size, 0.5)
    return y, ok


def _orthonormal(X, scale) -> np.ndarray:
    """Orthonormal columns spanning each leaf's X (K, Lmax, q), as many as its rank; the rest come out zero.

    Symmetric orthonormalisation through each leaf's Gram matrix, twice (the second pass removes the first's
    rounding): it keeps the span exactly, and a direction whose singular value is below DEPENDENT times the
    leaf's ``scale`` (K,) (the size of the vectors before anything was taken out of them) is dropped, whatever
    its position (a QR would bend the columns after a dependent one).
    """
    if X.shape[2] == 0:
        return X
    tiny = np.finfo(np.float64).tiny
    floor = np.maximum(np.square(DEPENDENT * scale), tiny)[:, None]
    for _ in range(2):
        w, V = np.linalg.eigh(X.swapaxes(-1, -2) @ X)
        keep = w > floor
        X = X @ (V * np.where(keep, 1.0 / np.sqrt(np.maximum(w, tiny)), 0.0)[:, None, :])
        floor = np.full_like(floor, 0.25)              # the second pass: kept directions have unit length
    return X


def _size(X) -> np.ndarray:
    """Each leaf's largest column norm of X (K, Lmax, q)."""
    return np.sqrt(np.square(X).sum(1).max(1)) if X.shape[2] else np.zeros(X.shape[0])


def _padded(lay, X) -> np.ndarray:
    """(n, k) rows in the leaves' order as the padded (K, Lmax, k), zero on the padding."""
    K, L = lay.shape
    Y = np.zeros((K * L, X.shape[1]))
    Y[lay.pos] = X
    return Y.reshape(K, L, -1)


def without(X, C):
    """X (K, Lmax, q) minus its components along the orthonormal columns C (K, Lmax, c) of each leaf (numpy
    arrays or torch tensors)."""
    return X - C @ (C.swapaxes(-1, -2) @ X)


def basis(lay, constants, start_vectors=None, solve=None, extra=0, S=None, diag=None, tol=0.0, fixed=None) -> tuple:
    """The coarse vectors of every leaf, padded: (K, Lmax, f + q + extra + c).

    Parameters
    ----------
    lay : LeafLayout
    constants : numpy.ndarray (K, Lmax, c)
        :func:`piece_constants` of the layout.
    start_vectors : numpy.ndarray (n, q + extra), optional
        Seeds in the leaves' row order (None: the piece constants alone, the 'const' space).
    solve : callable
        (n, q) -> S^-1 (n, q).
    extra : int
        How many of the seeds (the last ones) are extras, kept by their Ritz value.
    S : callable, optional
        (n, k) -> S (n, k) (needed with ``extra``).
    diag : numpy.ndarray (n,), optional
        S's diagonal (needed with ``extra``).
    tol : float
    fixed : numpy.ndarray (n, f), optional
        Vectors taken as they are (the near null space, :mod:`.nearnull`), first, each leaf's part made orthonormal
        and orthogonal to its constants; the seeds' vectors are made orthogonal to them too.

    Returns
    -------
    P : numpy.ndarray (K, Lmax, f + q + extra + c)
        Zero on the padding and in unused columns.
    kept : numpy.ndarray (K,)
        Nonzero columns per leaf.
    """
    K, L = lay.shape
    blocks, ahead = [], constants                    # ahead: what later vectors are made orthogonal to
    if fixed is not None:
        Z = _padded(lay, fixed)
        blocks = [_orthonormal(without(Z, constants), _size(Z))]
        ahead = np.concatenate([blocks[0], constants], axis=2)
    if start_vectors is not None:
        Y = _padded(lay, solve(start_vectors))
        q = Y.shape[2] - extra
        blocks.append(_orthonormal(without(Y[:, :, :q], ahead), _size(Y[:, :, :q])))
        if extra:
            rest = _orthonormal(without(without(Y[:, :, q:], ahead), blocks[-1]), _size(Y[:, :, q:]))
            SX = np.zeros((K * L, extra))
            SX[lay.pos] = S(rest.reshape(K * L, -1)[lay.pos])
            theta, U = np.linalg.eigh(rest.mT @ SX.reshape(K, L, -1))
            rest = rest @ U
            scale = np.bincount(lay.leaf, np.abs(diag), minlength=K) / lay.leaves.sizes
            blocks.append(rest * (theta <= tol * scale[:, None])[:, None, :])
    P = np.concatenate(blocks + [constants], axis=2)
    kept = (np.abs(P).sum(1) > 0).sum(1)
    return P, kept
