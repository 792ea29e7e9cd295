"""Row orderings for sparse operators: Morton, reverse Cuthill-McKee, natural."""
import numpy as np
import scipy.sparse as sp

from .morton import morton_permutation, quantized_morton_codes
from .twolevel.cuthill import reverse_cuthill_mckee

METHODS = ("auto", "morton", "rcm", "natural")


def check_square(A):
    """Return ``A`` as CSR, or raise ValueError unless it is square sparse."""
    if not sp.issparse(A) or A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"A must be a square scipy sparse matrix, got {type(A).__name__} "
                         f"of shape {getattr(A, 'shape', None)}")
    return sp.csr_matrix(A)


def check_coords(coords, n):
    """Return ``coords`` as a float (n, 2) or (n, 3) array, or raise ValueError."""
    pts = np.asarray(coords, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[0] != n or pts.shape[1] not in (2, 3):
        raise ValueError(f"coords must have shape ({n}, 2) or ({n}, 3), got {pts.shape}")
    return pts


def rcm_permutation(A):
    """Reverse Cuthill-McKee ordering of a structurally symmetric matrix.

    Returns
    -------
    numpy.ndarray of int64
        ``p`` such that ``A[p][:, p]`` has reduced bandwidth.
    """
    A = check_square(A)
    return reverse_cuthill_mckee(A)


def is_morton_sorted(coords):
    """True when the points already come in Morton order.

    The quantised Morton codes (see
    :func:`petsc_htp.morton.quantized_morton_codes`) must be non-decreasing.
    """
    codes = quantized_morton_codes(coords)
    return bool(np.all(codes[1:] >= codes[:-1]))


def choose_ordering(A, coords=None, method="auto"):
    """Pick a symmetric permutation for ``A``.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
    coords : array_like, shape (N, 2) or (N, 3), optional
        Point coordinates of the rows.
    method : {'auto', 'morton', 'rcm', 'natural'}
        'auto' keeps rows already in Morton order ("morton (given)"), else
        uses Morton order when ``coords`` are given and RCM otherwise.

    Returns
    -------
    perm : numpy.ndarray of int64
        ``p`` such that ``A[p][:, p]`` is the reordered matrix.
    name : str
        The ordering used.
    """
    if method not in METHODS:
        raise ValueError(f"unknown ordering method {method!r}; expected one of "
                         f"{', '.join(METHODS)}")
    A = check_square(A)
    n = A.shape[0]
    pts = None if coords is None else check_coords(coords, n)
    if method == "natural":
        return np.arange(n, dtype=np.int64), "natural"
    if method == "rcm" or (method == "auto" and pts is None):
        return rcm_permutation(A), "rcm"
    if pts is None:
        raise ValueError("ordering method 'morton' needs coordinates (coords=None given)")
    if method == "auto" and is_morton_sorted(pts):
        return np.arange(n, dtype=np.int64), "morton (given)"
    return morton_permutation(pts), "morton"


def permuted_pattern(A, perm):
    """``A[perm][:, perm]`` with sorted indices, and where each of its entries sits in ``A.data``.

    Returns
    -------
    Ap : scipy.sparse.csr_matrix
        The permuted matrix.
    data_map : numpy.ndarray of int64
        ``Ap.data == A.data[data_map]``: a later matrix with ``A``'s pattern is permuted by
        this gather alone.
    """
    A = check_square(A)
    if not A.has_canonical_format:
        raise ValueError("A must be in canonical CSR form (sorted indices, no duplicates)")
    ids = sp.csr_matrix((np.arange(1, A.nnz + 1, dtype=np.float64), A.indices, A.indptr), shape=A.shape)
    P = ids[perm][:, perm]                    # ids start at 1: no entry is an explicit zero
    P.sort_indices()
    data_map = P.data.astype(np.int64) - 1
    return sp.csr_matrix((A.data[data_map], P.indices, P.indptr), shape=A.shape), data_map
