"""Two-level preconditioner: exact leaf solves plus an exact Galerkin coarse solve.

    M r = Q r + (I - Q A) B (I - A Q) r,    Q = P (P^T A P)^-1 P^T,

with B the inverses of A's diagonal leaf blocks (block Jacobi) and P a block-diagonal
coarse basis of r vectors per leaf. M is symmetric positive definite by construction
(balanced / deflation form). Setup comes in two steps: :func:`analyse` (nonzero pattern
only) and :func:`factor` (values; every frame of a time-stepping solver). Everything is
float64 torch on the analysis' device; vectors inside are padded to (K, Lmax) per leaf.
"""
from __future__ import annotations

import numbers
import time
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import connected_components

from .checks import probe_reason
from .leaves import Leaves
from .ordering import _check_square

COARSE_KINDS = ("const", "eig", "given", "seeded")
NULL_TOL = 1e-10            # |A 1_c| <= NULL_TOL * max diag: component c is singular
SPAN_TOL = 1e-8             # |z - P P^T z|^2 / |z|^2 below this: z in null(A) lies in P's span
PIVOT_TOL = 1e-14           # Cholesky pivot below this times the largest diagonal: singular
DEAD_TOL = 1e-10            # Gram eigenvalue ratio below which a given basis vector is dropped
SHIFTS = (1e-12, 1e-9, 1e-6, 1e-3, 2.0)   # Cholesky fallback shifts, times the row-sum bound
EIG_OVERSAMPLE = 0          # extra subspace-iteration vectors for coarse='eig' (4: CG +20 % at N = 16384)
EIG_STEPS = 1               # inverse-iteration steps for 'eig' (2: CG +20 %; converged vectors are worse)
EIG_SHIFT = 1e-8            # Neumann matrix shift for the iteration, times the mean diagonal (null modes to 1e-8)
MAX_COARSE = 8192           # largest K r for the dense coarse operator
DTYPE = torch.float64


def _ms(t0, device):
    """Milliseconds since ``t0``, after the device has finished its queued work."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return (time.perf_counter() - t0) * 1e3


@dataclass(frozen=True, eq=False)
class TwoLevelAnalysis:
    """What depends on A's nonzero pattern only (the caller's CSR entry order included).

    Padded positions: permuted row ``i`` of leaf k sits at ``k * Lmax + i - offsets[k]``.

    Attributes
    ----------
    leaves : Leaves
    device : torch.device
    nnz : int
        Stored entries of the analysed A.
    pos : Tensor (N,)
        Padded position of each permuted row.
    mask : Tensor (K, Lmax)
        1.0 on real rows, 0.0 on padding.
    crow, col, csr_src : Tensor
        Padded CSR structure of the permuted A and the A.data entry of each of its values.
    in_src, in_dst : Tensor
        A.data entries inside a leaf and their flat index in the (K, Lmax, Lmax) blocks.
    off_src, off_row, off_col : Tensor
        A.data entries coupling two leaves, with their padded row and column.
    comp : Tensor (K * Lmax,)
        Connected component of each padded row (-1 on padding).
    comp_local : Tensor (C,)
        True for components that lie inside one leaf.
    comp_size : Tensor (C,)
        Rows per component.
    analysis_ms : float
    """

    leaves: Leaves
    device: torch.device
    nnz: int
    pos: torch.Tensor
    mask: torch.Tensor
    crow: torch.Tensor
    col: torch.Tensor
    csr_src: torch.Tensor
    in_src: torch.Tensor
    in_dst: torch.Tensor
    off_src: torch.Tensor
    off_row: torch.Tensor
    off_col: torch.Tensor
    comp: torch.Tensor
    comp_local: torch.Tensor
    comp_size: torch.Tensor
    analysis_ms: float

    @property
    def n(self) -> int:
        """Number of rows N."""
        return self.leaves.n

    @property
    def shape(self) -> tuple:
        """(K, Lmax)."""
        return self.leaves.n_leaves, self.leaves.max_size


def _padded_positions(leaves):
    """Padded position of each permuted row, shape (N,)."""
    sizes = leaves.sizes
    leaf_of = np.repeat(np.arange(leaves.n_leaves), sizes)
    return leaf_of * leaves.max_size + np.arange(leaves.n) - leaves.offsets[leaf_of]


def _components(A, pos_caller, n_leaves, lmax):
    """Component of each padded row, whether each component sits in one leaf, its size."""
    pattern = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    n_comp, labels = connected_components(pattern, directed=False)
    comp = np.full(n_leaves * lmax, -1, dtype=np.int64)
    comp[pos_caller] = labels
    leaf = pos_caller // lmax
    lo = np.full(n_comp, n_leaves)
    hi = np.full(n_comp, -1)
    np.minimum.at(lo, labels, leaf)
    np.maximum.at(hi, labels, leaf)
    return comp, lo == hi, np.bincount(labels, minlength=n_comp)


def analyse(A, leaves: Leaves, device="cpu") -> TwoLevelAnalysis:
    """Per-pattern setup: padded CSR structure, block and coupling maps, components.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Only its pattern and entry order are used.
    leaves : Leaves
        Leaves of N rows.
    device : str or torch.device
    """
    t0 = time.perf_counter()
    A = _check_square(A)
    if leaves.n != A.shape[0]:
        raise ValueError(f"leaves cover {leaves.n} rows but A has {A.shape[0]}")
    device = torch.device(device)
    (K, L), n = (leaves.n_leaves, leaves.max_size), leaves.n
    pos = _padded_positions(leaves)
    pos_caller = np.empty(n, dtype=np.int64)
    pos_caller[leaves.perm] = pos
    pr = pos_caller[np.repeat(np.arange(n), np.diff(A.indptr))]
    pc = pos_caller[A.indices]
    inside = pr // L == pc // L
    order = np.lexsort((pc, pr))
    mask = np.zeros(K * L)
    mask[pos] = 1.0
    comp, local, size = _components(A, pos_caller, K, L)
    as_t = lambda a, dtype=torch.int64: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
    return TwoLevelAnalysis(
        leaves=leaves, device=device, nnz=A.nnz, pos=as_t(pos), mask=as_t(mask, DTYPE).view(K, L),
        crow=as_t(np.concatenate(([0], np.cumsum(np.bincount(pr, minlength=K * L))))),
        col=as_t(pc[order]), csr_src=as_t(order),
        in_src=as_t(np.flatnonzero(inside)), in_dst=as_t(pr[inside] * L + pc[inside] % L),
        off_src=as_t(np.flatnonzero(~inside)), off_row=as_t(pr[~inside]), off_col=as_t(pc[~inside]),
        comp=as_t(comp), comp_local=as_t(local, torch.bool), comp_size=as_t(size, DTYPE),
        analysis_ms=_ms(t0, device))


# ------------------------------------------------------------------ numeric pieces

def _values(analysis, A):
    """A.data as a float64 tensor, after checking shape, pattern size and finiteness."""
    A = _check_square(A)
    if A.shape[0] != analysis.n or A.nnz != analysis.nnz:
        raise ValueError(f"A does not match the analysed pattern: shape {A.shape}, nnz {A.nnz}; "
                         f"analysed N={analysis.n}, nnz={analysis.nnz}")
    if not np.all(np.isfinite(A.data)):
        raise ValueError("A has non-finite entries (NaN or Inf)")
    return torch.as_tensor(A.data, dtype=DTYPE, device=analysis.device)


def _csr(analysis, data):
    """The permuted, padded A as a torch sparse CSR tensor."""
    n_pad = analysis.mask.numel()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)      # "sparse CSR support is in beta"
        return torch.sparse_csr_tensor(analysis.crow, analysis.col, data[analysis.csr_src],
                                       size=(n_pad, n_pad), check_invariants=False)


def _blocks(analysis, data):
    """Diagonal leaf blocks (K, Lmax, Lmax); the padding gets the leaf's largest |diagonal|."""
    K, L = analysis.shape
    blocks = torch.zeros(K * L * L, dtype=DTYPE, device=analysis.device)
    blocks.index_add_(0, analysis.in_dst, data[analysis.in_src])
    blocks = blocks.view(K, L, L)
    diag = blocks.diagonal(dim1=1, dim2=2)
    top = diag.abs().amax(1, keepdim=True)
    diag.add_((1.0 - analysis.mask) * torch.where(top > 0, top, 1.0))
    return blocks


def _null_components(analysis, A_csr, dmax):
    """Boolean (C,): components whose constant A annihilates (|A 1_c| <= NULL_TOL max diag)."""
    real = analysis.comp >= 0
    rowsum = torch.mv(A_csr, analysis.mask.reshape(-1)).abs()[real]
    res = torch.zeros_like(analysis.comp_size)
    res.scatter_reduce_(0, analysis.comp[real], rowsum, "amax")
    return res <= NULL_TOL * dmax


def _cholesky(X):
    """Batched Cholesky factors and which of them are sound (no breakdown, no tiny pivot)."""
    chol, info = torch.linalg.cholesky_ex(X)
    pivot = chol.diagonal(dim1=-2, dim2=-1).square().amin(-1)
    return chol, (info == 0) & (pivot > PIVOT_TOL * X.diagonal(dim1=-2, dim2=-1).abs().amax(-1))


def _spd_inverse(X):
    """Inverses of a batch of symmetric matrices by Cholesky; singular blocks get shifted.

    Returns
    -------
    inv : Tensor
        Symmetric inverses.
    shift : float
        Largest shift used, relative to the row-sum bound (0.0 when none was needed).
    count : int
        Number of shifted blocks.
    """
    chol, ok = _cholesky(X)
    bad = (~ok).nonzero().flatten()
    shift = 0.0
    if bad.numel():
        bound = X[bad].abs().sum(-1).amax(-1)
        bound = torch.where(bound > 0, bound, 1.0)
        eye = torch.eye(X.shape[-1], dtype=DTYPE, device=X.device)
        for shift in SHIFTS:
            fixed, ok = _cholesky(X[bad] + (shift * bound)[:, None, None] * eye)
            if ok.all():
                break
        chol[bad] = fixed
    inv = torch.cholesky_inverse(chol)
    if inv.device.type != "cpu":             # LAPACK's potri result is exactly symmetric
        inv = 0.5 * (inv + inv.mT)
    return inv, shift, int(bad.numel())


def _local_null_fix(analysis, blocks, null):
    """Rank-one terms s_k 1_c 1_c^T / |c| for null components c inside one leaf (else None)."""
    K, L = analysis.shape
    target = null & analysis.comp_local
    if not target.any():
        return None
    comp = analysis.comp.view(K, L)
    hit = (comp >= 0) & target[comp.clamp_min(0)]
    label = torch.where(hit, comp, -1)
    same = (label[:, :, None] == label[:, None, :]) & hit[:, :, None]
    weight = 1.0 / analysis.comp_size[comp.clamp_min(0)]
    s = (blocks.diagonal(dim1=1, dim2=2) * analysis.mask).sum(1) / analysis.mask.sum(1)
    return same * (s[:, None] * weight)[:, :, None]


def _leaf_inverses(analysis, blocks, null):
    """Inverses of the leaf blocks, exact (pseudo-inverse-like) for whole null components."""
    fix = _local_null_fix(analysis, blocks, null)
    inv, shift, count = _spd_inverse(blocks if fix is None else blocks + fix)
    note = f"{count} leaf block(s) shifted by {shift:g} x row-sum bound" if count else ""
    return inv, note


# ------------------------------------------------------------------ coarse spaces

def _shifted_neumann(analysis, blocks, data):
    """Local Neumann matrices plus EIG_SHIFT x their mean |diagonal| on the real rows.

    The Neumann matrix is the leaf block with each row's off-leaf couplings added to its
    diagonal: for an M-matrix, their magnitudes taken off. It keeps A's row sums, so where
    those are zero the constant is its first mode.
    """
    K, L = analysis.shape
    mask = analysis.mask
    offsum = torch.zeros(K * L, dtype=DTYPE, device=analysis.device)
    offsum.index_add_(0, analysis.off_row, data[analysis.off_src])
    S = blocks.clone()
    diag = S.diagonal(dim1=1, dim2=2)
    diag.add_(offsum.view(K, L))
    mean = (diag * mask).abs().sum(1) / mask.sum(1)
    diag.add_(EIG_SHIFT * mean[:, None] * mask)
    return S


def _eigh_modes(S, mask, r):
    """The r lowest eigenvectors of each real block by full eigh (zero columns past its size)."""
    top = 2.0 * S.abs().sum(-1).amax(-1) + 1.0
    S = S.clone()
    S.diagonal(dim1=1, dim2=2).add_((1.0 - mask) * top[:, None])
    V = torch.linalg.eigh(S)[1][:, :, :r] * mask[:, :, None]
    return torch.nn.functional.pad(V, (0, r - V.shape[2]))


def _seeds(mask, q):
    """q smooth start vectors per leaf: cos(pi j (i + 1/2) / n_k) in the leaf's local order."""
    K, L = mask.shape
    i = torch.arange(L, dtype=DTYPE, device=mask.device) + 0.5
    j = torch.arange(q, dtype=DTYPE, device=mask.device)
    angle = torch.pi * i[None, :, None] * j[None, None, :] / mask.sum(1)[:, None, None]
    return torch.cos(angle) * mask[:, :, None]


def _subspace_modes(S, mask, r, chol, seeds=None):
    """Approximate r lowest eigenvectors: block inverse iteration with S from ``seeds``
    (default: the smoothest cosines), then Rayleigh-Ritz."""
    X = _seeds(mask, r + EIG_OVERSAMPLE) if seeds is None else seeds
    for _ in range(EIG_STEPS):
        Y = torch.linalg.solve_triangular(chol, X, upper=False)         # batched cholesky_solve is
        Y = torch.linalg.solve_triangular(chol.mT, Y, upper=True)       # several times slower on CPU
        X = torch.linalg.qr(Y)[0] * mask[:, :, None]
    ritz = torch.linalg.eigh(X.mT @ (S @ X))[1][:, :, :r]
    return X @ ritz


def _eig_basis(analysis, blocks, data, r, seeds=None):
    """Coarse basis of r low eigenvectors of each leaf's local Neumann matrix.

    Subspace iteration where the shifted Neumann matrix has a Cholesky factor and the leaf
    has more than r + EIG_OVERSAMPLE rows; full eigh on the other leaves.
    """
    S = _shifted_neumann(analysis, blocks, data)
    mask = analysis.mask
    chol, info = torch.linalg.cholesky_ex(S)
    bad = (info != 0) | (mask.sum(1) <= r + EIG_OVERSAMPLE)
    P = torch.zeros(*mask.shape, r, dtype=DTYPE, device=mask.device)
    if not bad.all():
        chol[bad] = torch.eye(chol.shape[-1], dtype=DTYPE, device=chol.device)
        P = _subspace_modes(S, mask, r, chol, seeds)
    if bad.any():
        P[bad] = _eigh_modes(S[bad], mask[bad], r)
    return P


def _given_basis(analysis, basis):
    """Orthonormalised caller basis (K, Lmax, r); near-dependent directions become zero columns.

    Symmetric orthonormalisation through each leaf's Gram matrix keeps the span exactly and
    drops directions whose Gram eigenvalue is below DEAD_TOL times the leaf's largest.
    """
    K, L = analysis.shape
    X = torch.as_tensor(basis, dtype=DTYPE, device=analysis.device)
    if X.ndim != 3 or X.shape[:2] != (K, L) or X.shape[2] < 1:
        raise ValueError(f"basis must have shape (K, Lmax, r) = ({K}, {L}, r >= 1), "
                         f"got {tuple(X.shape)}")
    if not torch.isfinite(X).all():
        raise ValueError("basis has non-finite entries")
    X = X * analysis.mask[:, :, None]
    w, V = torch.linalg.eigh(X.mT @ X)
    keep = w > DEAD_TOL * w[:, -1:].clamp_min(torch.finfo(DTYPE).tiny)
    scale = torch.where(keep, w.clamp_min(torch.finfo(DTYPE).tiny).rsqrt(), torch.zeros_like(w))
    return X @ (V * scale[:, None, :])


def _coarse_basis(analysis, blocks, data, coarse, rank, basis):
    """Coarse basis P (K, Lmax, r), zero on the padding, orthonormal columns or zero columns."""
    if coarse == "const":
        return (analysis.mask / analysis.mask.sum(1, keepdim=True).sqrt())[:, :, None]
    if coarse == "eig":
        return _eig_basis(analysis, blocks, data, rank)
    if coarse == "seeded":
        seeds = _given_basis(analysis, basis)
        return _eig_basis(analysis, blocks, data, seeds.shape[2], seeds)
    return _given_basis(analysis, basis)


# ------------------------------------------------------------------ coarse operator

def _galerkin(analysis, blocks, data, P):
    """Dense A_c = P^T A P: leaf blocks by bmm, couplings entry by entry."""
    K, L = analysis.shape
    r = P.shape[2]
    Ac = torch.zeros(K, r, K, r, dtype=DTYPE, device=P.device)
    ar = torch.arange(K, device=P.device)
    Ac[ar, :, ar, :] = P.mT @ blocks @ P
    flat = P.reshape(K * L, r)
    rows, cols = analysis.off_row, analysis.off_col
    outer = data[analysis.off_src][:, None, None] * flat[rows][:, :, None] * flat[cols][:, None, :]
    a = torch.arange(r, device=P.device)
    idx = (((rows // L) * r)[:, None, None] + a[:, None]) * (K * r) + ((cols // L) * r)[:, None, None] + a
    Ac.view(-1).index_add_(0, idx.reshape(-1), outer.reshape(-1))
    return Ac.view(K * r, K * r)


def _coarse_null_space(analysis, P, null):
    """Orthonormal basis (Kr, m) of A_c's null space {P^T z : z in null(A) and in P's span}.

    null(A) is spanned by the constants 1_c of the null components (columns of Z). P^T Z a is
    null for A_c exactly when Z a lies in P's span, i.e. when a is in the kernel of
    I - Cn^T Cn with Cn = P^T Z |c|^-1/2; then Cn a is a unit null vector of A_c.
    """
    K, L = analysis.shape
    r = P.shape[2]
    comp = analysis.comp
    rows = ((comp >= 0) & null[comp.clamp_min(0)]).nonzero().flatten()
    col = (torch.cumsum(null, 0) - 1)[comp[rows]].repeat_interleave(r)
    dof = (((rows // L) * r)[:, None] + torch.arange(r, device=P.device)).reshape(-1)
    C = torch.zeros(K * r, int(null.sum()), dtype=DTYPE, device=P.device)
    C.index_put_((dof, col), P.reshape(K * L, r)[rows].reshape(-1), accumulate=True)
    C *= analysis.comp_size[null].rsqrt()
    w, U = torch.linalg.eigh(torch.eye(C.shape[1], dtype=DTYPE, device=P.device) - C.mT @ C)
    return C @ U[:, w <= SPAN_TOL]


def _coarse_inverse(analysis, Ac, P, null, dmax):
    """A_c^-1 with its null space (from A's) and dropped basis columns lifted by s; and a note.

    s is A_c's mean diagonal (A's largest diagonal when that vanishes). With Y an orthonormal
    basis of null(A_c), (A_c + s Y Y^T)^-1 equals A_c's pseudo-inverse on consistent residuals.
    """
    Y = _coarse_null_space(analysis, P, null)
    diag = Ac.diagonal()
    live = P.norm(dim=1).reshape(-1) > 0.5
    s = diag[live].mean() if live.any() else dmax
    s = s if s > NULL_TOL * dmax else dmax
    diag.add_(torch.where(live, 0.0, s))
    Ac.addmm_(Y, Y.mT, alpha=float(s))
    inv, shift, _ = _spd_inverse(Ac[None])
    notes = [f"{Y.shape[1]} null direction(s) deflated"] if Y.shape[1] else []
    notes += [f"Cholesky failed: shifted by {shift:g} x row-sum bound"] if shift else []
    return inv[0], "; ".join(notes) or "exact"


# ------------------------------------------------------------------ the operator

class TwoLevel:
    """The factored two-level preconditioner M (see the module docstring).

    Attributes
    ----------
    n, rank, coarse_size : int
        N, vectors per leaf r and K * r.
    coarse : str
        'const', 'eig', 'given' or 'seeded'.
    coarse_note, leaf_note : str
        What the coarse and leaf factorisations had to fix ('exact' / '' when nothing).
    times : dict
        Setup times in ms: 'leaf', 'coarse_space', 'coarse_operator'.
    """

    def __init__(self, analysis, A_csr, leaf_inv, P, coarse_inv, coarse, notes, times):
        self.analysis = analysis
        self.coarse = coarse
        self.coarse_note, self.leaf_note = notes
        self.times = times
        self._A, self._B, self._P, self._Ainv_c = A_csr, leaf_inv, P, coarse_inv
        K, L = analysis.shape
        self.n, self.rank = analysis.n, P.shape[2]
        self.coarse_size = K * self.rank
        new = lambda *shape: torch.zeros(*shape, dtype=DTYPE, device=analysis.device)  # noqa: E731
        self._r, self._t, self._u, self._v = (new(K * L) for _ in range(4))
        self._c, self._y = new(K, self.rank, 1), new(K * self.rank)

    @property
    def basis(self) -> torch.Tensor:
        """The coarse basis P, shape (K, Lmax, r) in padded leaf layout (zero columns: dropped)."""
        return self._P

    @property
    def nbytes(self) -> int:
        """Bytes held: leaf inverses, P, coarse inverse and the padded CSR of A."""
        A = self._A
        held = (self._B, self._P, self._Ainv_c, A.crow_indices(), A.col_indices(), A.values())
        return sum(t.numel() * t.element_size() for t in held)

    def _coarse_solve(self, x, out):
        """out = P A_c^-1 P^T x (padded vectors)."""
        K, L = self.analysis.shape
        torch.bmm(self._P.mT, x.view(K, L, 1), out=self._c)
        torch.mv(self._Ainv_c, self._c.view(-1), out=self._y)
        torch.bmm(self._P, self._y.view(K, self.rank, 1), out=out.view(K, L, 1))

    def _residual(self, x, out):
        """out = r - A x, with r the padded input in ``self._r``."""
        torch.mv(self._A, x, out=out)
        torch.sub(self._r, out, out=out)

    def apply_(self, r: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """z = M r for device vectors in the leaves' permuted order; device ops only.

        Uses preallocated work buffers (not re-entrant). As
        ``t = Q r; v = B (r - A t); z = v + Q (r - A v)``.
        """
        K, L = self.analysis.shape
        pos = self.analysis.pos
        self._r.index_copy_(0, pos, r)
        self._coarse_solve(self._r, self._t)
        self._residual(self._t, self._u)
        torch.bmm(self._B, self._u.view(K, L, 1), out=self._v.view(K, L, 1))
        self._residual(self._v, self._u)
        self._coarse_solve(self._u, self._t)
        self._t.add_(self._v)
        return torch.index_select(self._t, 0, pos, out=z)

    def apply(self, r: np.ndarray) -> np.ndarray:
        """z = M r in the caller's row order, float64 in and out."""
        r = np.asarray(r, dtype=np.float64)
        if r.shape != (self.n,):
            raise ValueError(f"r must have shape ({self.n},), got {r.shape}")
        perm = self.analysis.leaves.perm
        rt = torch.as_tensor(r[perm], device=self.analysis.device)
        z = np.empty(self.n)
        z[perm] = self.apply_(rt, torch.empty_like(rt)).cpu().numpy()
        return z

    @torch.no_grad()
    def load_(self, other: "TwoLevel") -> None:
        """Copy the factors of ``other`` (same analysis and rank) into this operator's buffers in place."""
        if other.analysis is not self.analysis or other.rank != self.rank:
            raise ValueError("load_ needs a TwoLevel of the same analysis and rank")
        for dst, src in ((self._B, other._B), (self._P, other._P), (self._Ainv_c, other._Ainv_c),
                         (self._A.values(), other._A.values())):
            dst.copy_(src)
        self.coarse_note, self.leaf_note, self.times = other.coarse_note, other.leaf_note, other.times

    def check(self, probes: int) -> str:
        """Empty when M is finite and positive on ``probes`` random vectors, else the reason."""
        return probe_reason(self.apply, self.n, probes, "two-level")

    def describe(self) -> list:
        """Short lines: leaves, coarse space, notes, setup times, memory."""
        lv = self.analysis.leaves
        t = self.times
        lines = [f"leaves: {lv.kind}, K={lv.n_leaves}, sizes {lv.sizes.min()}-{lv.max_size}",
                 f"coarse: {self.coarse}, r={self.rank}, size {self.coarse_size}, {self.coarse_note}",
                 f"setup ms: analysis {self.analysis.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                 f"leaf {t['leaf']:.1f}, coarse space {t['coarse_space']:.1f}, coarse operator {t['coarse_operator']:.1f}",
                 "apply: float64 (a linear operator to working precision: any KSP, any rtol)",
                 f"memory: {self.nbytes / self.n:.0f} bytes per unknown"]
        return lines + ([f"leaf blocks: {self.leaf_note}"] if self.leaf_note else [])


def leaf_stage(analysis: TwoLevelAnalysis, A) -> tuple:
    """Values, padded CSR, leaf blocks, largest |diagonal|, null components, leaf inverses and their note."""
    data = _values(analysis, A)
    A_csr = _csr(analysis, data)
    blocks = _blocks(analysis, data)
    dmax = (blocks.diagonal(dim1=1, dim2=2) * analysis.mask).abs().max()
    null = _null_components(analysis, A_csr, dmax)
    leaf_inv, leaf_note = _leaf_inverses(analysis, blocks, null)
    return data, A_csr, blocks, dmax, null, leaf_inv, leaf_note


def coarse_space(analysis: TwoLevelAnalysis, A, coarse="eig", rank=4, basis=None) -> torch.Tensor:
    """The coarse basis P alone, (K, Lmax, r) in the padded leaf layout (no leaf inverses, no coarse operator).

    Parameters as in :func:`factor`.
    """
    if coarse not in COARSE_KINDS:
        raise ValueError(f"unknown coarse kind {coarse!r}; expected one of {', '.join(COARSE_KINDS)}")
    data = _values(analysis, A)
    return _coarse_basis(analysis, _blocks(analysis, data), data, coarse, rank, basis)


def factor(analysis: TwoLevelAnalysis, A, coarse="eig", rank=4, basis=None) -> TwoLevel:
    """Per-values setup: leaf inverses, coarse space, Galerkin coarse operator and its inverse.

    Parameters
    ----------
    analysis : TwoLevelAnalysis
        From :func:`analyse` on a matrix with A's pattern and entry order.
    A : scipy.sparse matrix
        The values to factor.
    coarse : {'const', 'eig', 'given', 'seeded'}
        Constant per leaf (r = 1); ``rank`` approximate low local Neumann eigenvectors per leaf (one
        inverse-iteration step from smooth seeds); ``basis`` as given; or the same step from ``basis``
        ('seeded': HTPPC's learned coarse space).
    rank : int
        Vectors per leaf for 'eig' (ignored otherwise).
    basis : array_like or Tensor, shape (K, Lmax, r), optional
        The coarse vectors for 'given' and 'seeded', in padded leaf layout, zero on the padding.
    """
    if coarse not in COARSE_KINDS:
        raise ValueError(f"unknown coarse kind {coarse!r}; expected one of {', '.join(COARSE_KINDS)}")
    if coarse == "eig" and (isinstance(rank, bool) or not isinstance(rank, numbers.Integral) or rank < 1):
        raise ValueError(f"rank must be a positive integer, got {rank!r}")
    if (coarse in ("given", "seeded")) != (basis is not None):
        raise ValueError("a basis is needed for coarse='given' or 'seeded' and only for them")
    device = analysis.device
    times = {}
    t0 = time.perf_counter()
    data, A_csr, blocks, dmax, null, leaf_inv, leaf_note = leaf_stage(analysis, A)
    times["leaf"] = _ms(t0, device)
    t0 = time.perf_counter()
    P = _coarse_basis(analysis, blocks, data, coarse, rank, basis)
    if P.shape[0] * P.shape[2] > MAX_COARSE:
        raise ValueError(f"coarse size K r = {P.shape[0]} x {P.shape[2]} exceeds {MAX_COARSE} "
                         "(dense coarse operator); use larger leaves or a smaller rank")
    times["coarse_space"] = _ms(t0, device)
    t0 = time.perf_counter()
    Ac = _galerkin(analysis, blocks, data, P)
    coarse_inv, coarse_note = _coarse_inverse(analysis, Ac, P, null, dmax)
    times["coarse_operator"] = _ms(t0, device)
    return TwoLevel(analysis, A_csr, leaf_inv, P, coarse_inv, coarse,
                    (coarse_note, leaf_note), times)
