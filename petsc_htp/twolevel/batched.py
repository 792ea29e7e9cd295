"""The two-level preconditioner in batched torch: PETSc-free, the GPU fast path's back-end.

    M r = Q r + (I - Q A) B (I - A Q) r,    Q = P (P^T A P)^-1 P^T     (the balanced form: SPD)

It is the method of :mod:`petsc_htp.twolevel.composed`, defined by the same parts: the leaves and their
pieces (:mod:`.leaflayout`, :mod:`.nullspace`), the null components and the pieces dropped and grounded
for them, the leaves' Neumann matrices and the coarse vectors (:mod:`.coarsespace`), the lift of unused
coarse columns. Here the leaf blocks and their inverses are dense per leaf, the Neumann step is a batched
dense Cholesky solve and the coarse operator is dense; everything is float64 on the analysis' device,
vectors padded to (K, Lmax) per leaf. Setup comes in two steps: :func:`analyse` (nonzero pattern only)
and :func:`factor` (values; every frame of a time-stepping solver).
"""
from __future__ import annotations

import numbers
import time
import warnings
from dataclasses import dataclass

import numpy as np
import torch

from ..checks import probe_reason
from ..ordering import check_square
from . import coarsespace, nullspace
from .csr import indptr_of, row_sums
from .leaflayout import LeafLayout, layout
from .leaves import Leaves

COARSE_KINDS = ("const", "eig", "given", "seeded")
PIVOT_TOL = 1e-14           # Cholesky pivot below this times the largest diagonal: singular
SHIFTS = (1e-12, 1e-9, 1e-6, 1e-3, 2.0)   # Cholesky fallback shifts, times the row-sum bound
MAX_COARSE = 8192           # largest coarse size for the dense coarse operator on the CPU
GPU_COARSE_SHARE = 1 / 12   # on a GPU: the largest whose float64 matrix takes this share of its memory
DTYPE = torch.float64


def _ms(t0, device):
    """Milliseconds since ``t0``, after the device has finished its queued work."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return (time.perf_counter() - t0) * 1e3


@dataclass(frozen=True, eq=False)
class TwoLevelAnalysis:
    """What depends on A's nonzero pattern only (the caller's CSR entry order included).

    Padded positions: row ``i`` of leaf k (in the leaves' order) sits at ``k * Lmax + i - offsets[k]``.

    Attributes
    ----------
    leaves : Leaves
    lay : LeafLayout
        The pattern's index maps, pieces and couplings between leaves (the PETSc back-end's too).
    device : torch.device
    nnz : int
        Stored entries of the analysed A.
    pos : Tensor (N,)
        Padded position of each row in the leaves' order.
    mask : Tensor (K, Lmax)
        1.0 on real rows, 0.0 on padding.
    crow, col, csr_src : Tensor
        Padded CSR structure of the permuted A and the A.data entry of each of its values.
    in_dst : Tensor
        Flat index in the (K, Lmax, Lmax) blocks of each of D's values (``lay.d_src`` order).
    diag_dst : Tensor (N,)
        Flat index of each row's diagonal in those blocks.
    off_src, off_row, off_col : Tensor
        A.data entries coupling two leaves, with their padded row and column.
    n_comp : int
        Connected components of A's nonzero graph.
    comp_of_row, comp_of_piece : numpy.ndarray
        Component of each of A's rows and of each piece.
    constants : Tensor (K, Lmax, c)
        The pieces' normalised constants (:func:`petsc_htp.twolevel.coarsespace.piece_constants`).
    analysis_ms : float
    """

    leaves: Leaves
    lay: LeafLayout
    device: torch.device
    nnz: int
    pos: torch.Tensor
    mask: torch.Tensor
    crow: torch.Tensor
    col: torch.Tensor
    csr_src: torch.Tensor
    in_dst: torch.Tensor
    diag_dst: torch.Tensor
    off_src: torch.Tensor
    off_row: torch.Tensor
    off_col: torch.Tensor
    n_comp: int
    comp_of_row: np.ndarray
    comp_of_piece: np.ndarray
    constants: torch.Tensor
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
    """Padded position of each row in the leaves' order, shape (N,)."""
    sizes = leaves.sizes
    leaf_of = np.repeat(np.arange(leaves.n_leaves), sizes)
    return leaf_of * leaves.max_size + np.arange(leaves.n) - leaves.offsets[leaf_of]


def analyse(A, leaves: Leaves, device="cpu") -> TwoLevelAnalysis:
    """Per-pattern setup: index maps and pieces (shared with PETSc's back-end), padded CSR and block maps.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Only its pattern and entry order are used (explicit zeros are not couplings).
    leaves : Leaves
        Leaves of N rows.
    device : str or torch.device
    """
    t0 = time.perf_counter()
    A = check_square(A)
    if leaves.n != A.shape[0]:
        raise ValueError(f"leaves cover {leaves.n} rows but A has {A.shape[0]}")
    device = torch.device(device)
    lay = layout(A, 0, leaves)
    (K, L), n = (leaves.n_leaves, leaves.max_size), leaves.n
    at = lay.pos[lay.iperm].astype(np.int64)                    # padded position of each of A's rows
    pr, pc = np.repeat(at, np.diff(A.indptr)), at[A.indices]
    order = np.lexsort((pc, pr))
    pos = lay.pos.astype(np.int64)
    d_rows = lay.d_leaf_row[np.repeat(np.arange(n), np.diff(lay.d_indptr))]     # leaves' order
    d_cols = lay.d_leaf_row[lay.d_indices]
    n_comp, comp_of_row = nullspace.graph_components(A)
    comp_of_piece = np.zeros(lay.pieces.n_pieces, dtype=np.int64)
    comp_of_piece[lay.pieces.label[lay.iperm]] = comp_of_row
    as_t = lambda a, dtype=torch.int64: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
    mask = np.zeros(K * L)
    mask[lay.pos] = 1.0
    return TwoLevelAnalysis(
        leaves=leaves, lay=lay, device=device, nnz=A.nnz, pos=as_t(lay.pos), mask=as_t(mask, DTYPE).view(K, L),
        crow=as_t(indptr_of(pr, K * L)),
        col=as_t(pc[order]), csr_src=as_t(order),
        in_dst=as_t(pos[d_rows] * L + pos[d_cols] % L), diag_dst=as_t(pos * L + pos % L),
        off_src=as_t(lay.o_src), off_row=as_t(at[lay.o_rows]), off_col=as_t(at[A.indices[lay.o_src]]),
        n_comp=n_comp, comp_of_row=comp_of_row, comp_of_piece=comp_of_piece,
        constants=torch.as_tensor(coarsespace.piece_constants(lay)).to(device), analysis_ms=_ms(t0, device))


# ------------------------------------------------------------------ numeric pieces

def checked_values(analysis, A):
    """A.data as a float64 tensor, after checking shape, pattern size and finiteness."""
    A = check_square(A)
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


def _blocks(analysis, d_values):
    """Dense leaf blocks (K, Lmax, Lmax) from D's values; the padding gets the leaf's largest |diagonal|."""
    K, L = analysis.shape
    blocks = torch.zeros(K * L * L, dtype=DTYPE, device=analysis.device)
    blocks.index_add_(0, analysis.in_dst, torch.as_tensor(d_values, dtype=DTYPE, device=analysis.device))
    blocks = blocks.view(K, L, L)
    diag = blocks.diagonal(dim1=1, dim2=2)
    top = diag.abs().amax(1, keepdim=True)
    diag.add_((1.0 - analysis.mask) * torch.where(top > 0, top, 1.0))
    return blocks


def _cholesky(X):
    """Batched Cholesky factors and which of them are sound (no breakdown, no tiny pivot)."""
    chol, info = torch.linalg.cholesky_ex(X)
    pivot = chol.diagonal(dim1=-2, dim2=-1).square().amin(-1)
    return chol, (info == 0) & (pivot > PIVOT_TOL * X.diagonal(dim1=-2, dim2=-1).abs().amax(-1))


def _spd_factor(X):
    """Batched Cholesky factors of symmetric matrices; blocks that break down get shifted.

    Returns
    -------
    chol : Tensor
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
    return chol, shift, int(bad.numel())


def _spd_inverse(X):
    """Inverses of a batch of symmetric matrices by Cholesky (see :func:`_spd_factor`): (inv, shift, count)."""
    chol, shift, count = _spd_factor(X)
    inv = torch.cholesky_inverse(chol)
    if inv.device.type != "cpu":             # LAPACK's potri result is exactly symmetric
        inv = 0.5 * (inv + inv.mT)
    return inv, shift, count


def max_coarse(device) -> int:
    """The largest dense coarse operator on ``device``: :data:`MAX_COARSE` on the CPU; on a GPU the size whose
    float64 matrix takes :data:`GPU_COARSE_SHARE` of the card's memory (its Cholesky and inverse take about four
    such matrices; the total, not the free memory, so a refresh that still holds the last frame's inverse gets the
    same limit), at least :data:`MAX_COARSE`."""
    if device.type != "cuda":
        return MAX_COARSE
    total = torch.cuda.get_device_properties(device).total_memory
    return max(MAX_COARSE, int((total * GPU_COARSE_SHARE / 8) ** 0.5))


def null_rule(analysis, A):
    """The null components by A's row sums, and the pieces to drop and ground (:mod:`.nullspace`)."""
    lay = analysis.lay
    rowsum = row_sums(A.indptr, A.data)
    null = nullspace.null_by_rowsums(rowsum, A.data[lay.d_src[lay.d_diag]], analysis.comp_of_row, analysis.n_comp)
    drop, ground = nullspace.dropped(null, analysis.comp_of_piece, lay.isolated)
    return null, drop, ground


def _leaf_values(analysis, A, ground):
    """D's values (in ``lay.d_src``'s order) with the grounded pieces' first diagonal entry raised."""
    lay = analysis.lay
    values = A.data[lay.d_src].astype(np.float64)
    if ground.any():
        nullspace.ground(values, lay.d_diag, nullspace.first_rows(lay.pieces.label, ground))
    return values


def _neumann_solver(analysis, A, d_values):
    """S's diagonal and ``solve``: S^-1 on (n, q) arrays in the leaves' order, by batched dense Cholesky."""
    lay = analysis.lay
    K, L = analysis.shape
    outside = np.bincount(lay.iperm[lay.o_rows], A.data[lay.o_src], minlength=lay.n)
    diag = coarsespace.neumann_diagonal(d_values[lay.d_diag], outside, lay.leaf, lay.leaves.sizes)
    S = _blocks(analysis, d_values).reshape(-1)
    S[analysis.diag_dst] = torch.as_tensor(diag, dtype=DTYPE, device=analysis.device)
    chol = _spd_factor(S.view(K, L, L))[0]

    def solve(X):
        Y = torch.zeros(K * L, X.shape[1], dtype=DTYPE, device=analysis.device)
        Y[analysis.pos] = torch.as_tensor(X, dtype=DTYPE, device=analysis.device)
        Y = torch.cholesky_solve(Y.view(K, L, -1), chol).reshape(K * L, -1)
        return Y[analysis.pos].cpu().numpy()
    return diag, solve


def _rows(analysis, basis):
    """A padded (K, Lmax, q) basis as (n, q) rows in the leaves' order, checked."""
    K, L = analysis.shape
    X = torch.as_tensor(basis, dtype=DTYPE)
    if X.ndim != 3 or X.shape[:2] != (K, L) or X.shape[2] < 1:
        raise ValueError(f"basis must have shape (K, Lmax, r) = ({K}, {L}, r >= 1), got {tuple(X.shape)}")
    if not torch.isfinite(X).all():
        raise ValueError("basis has non-finite entries")
    return X.reshape(K * L, -1).cpu()[torch.as_tensor(analysis.lay.pos)].numpy()


def _coarse_basis(analysis, A, d_values, coarse, rank, basis) -> torch.Tensor:
    """The coarse vectors (K, Lmax, q + c): 'const' the piece constants; 'eig' r - 1 vectors from the Neumann
    step and the constants; 'seeded' the step from ``basis``; 'given' ``basis`` made orthonormal, with them."""
    lay, constants = analysis.lay, analysis.constants.cpu().numpy()
    if coarse == "const":
        return torch.as_tensor(coarsespace.basis(lay, constants)[0])
    if coarse == "given":
        return torch.as_tensor(coarsespace.basis(lay, constants, _rows(analysis, basis), lambda X: X)[0])
    seeds = (_rows(analysis, basis) if coarse == "seeded"
             else coarsespace.seeds(lay.leaf, lay.leaves.offsets, lay.leaves.sizes, 1, rank - 1))
    if seeds.shape[1] == 0:
        return torch.as_tensor(coarsespace.basis(lay, constants)[0])
    _, solve = _neumann_solver(analysis, A, d_values)
    return torch.as_tensor(coarsespace.basis(lay, constants, seeds, solve)[0])


def dropped_columns(analysis, P, drop) -> torch.Tensor:
    """P with the dropped pieces' constant columns zeroed."""
    lay = analysis.lay
    pieces = np.flatnonzero(drop)
    if pieces.size:
        lead = P.shape[2] - analysis.constants.shape[2]
        leaf = lay.pieces.leaf[pieces]
        P = P.clone()
        P[torch.as_tensor(leaf), :, torch.as_tensor(lead + pieces - lay.pieces.first[leaf])] = 0.0
    return P


# ------------------------------------------------------------------ coarse operator

def galerkin(analysis, blocks, data, P):
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


def lifted(Ac):
    """A_c with its unused (all-zero) columns lifted on the diagonal, as the PETSc back-end lifts them."""
    return Ac + torch.diag(coarsespace.lift(Ac.diagonal()))


# ------------------------------------------------------------------ the operator

class BatchedTwoLevel:
    """The factored two-level preconditioner M (see the module docstring).

    Attributes
    ----------
    n, rank, coarse_size : int
        N, coarse vectors per leaf (columns, used or not) and K * rank.
    coarse : str
        'const', 'eig', 'given' or 'seeded'.
    coarse_note, leaf_note : str
        What the coarse and leaf factorisations had to fix ('' when nothing).
    null_components : int
        Null components whose constant was left out of the coarse space.
    times : dict
        Setup times in ms: 'leaf', 'coarse_space', 'coarse_operator'.
    """

    def __init__(self, analysis, A_csr, leaf_inv, P, coarse_inv, coarse, notes, null_components, times):
        self.analysis = analysis
        self.coarse = coarse
        self.coarse_note, self.leaf_note = notes
        self.null_components = null_components
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
        """The coarse basis P, shape (K, Lmax, r) in padded leaf layout (zero columns: unused)."""
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
        """z = M r for device vectors in the leaves' order; device ops only.

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
    def load_(self, other: "BatchedTwoLevel") -> None:
        """Copy the factors of ``other`` (same analysis and rank) into this operator's buffers in place."""
        if other.analysis is not self.analysis or other.rank != self.rank:
            raise ValueError("load_ needs a BatchedTwoLevel of the same analysis and rank")
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
        lines = [f"leaves: {lv.kind}, K={lv.n_leaves}, sizes {lv.sizes.min()}-{lv.max_size}; "
                 f"{self.analysis.lay.pieces.n_pieces} pieces",
                 f"coarse: {self.coarse}, r={self.rank}, size {self.coarse_size}, "
                 f"{self.null_components} null component(s) left out" + (f"; {self.coarse_note}" if self.coarse_note else ""),
                 f"setup ms: analysis {self.analysis.analysis_ms:.1f} (once per pattern; leaves {lv.build_ms:.1f}); "
                 f"leaf {t['leaf']:.1f}, coarse space {t['coarse_space']:.1f}, coarse operator {t['coarse_operator']:.1f}",
                 "apply: float64, balanced form (a linear operator to working precision: any KSP, any rtol)",
                 f"memory: {self.nbytes / self.n:.0f} bytes per unknown"]
        return lines + ([f"leaf blocks: {self.leaf_note}"] if self.leaf_note else [])


def leaf_stage(analysis: TwoLevelAnalysis, A) -> tuple:
    """The per-values leaf work: (values, padded CSR of A, leaf blocks of A, grounded D's values, dropped pieces,
    leaf inverses, their note, null components)."""
    data = checked_values(analysis, A)
    A_csr = _csr(analysis, data)
    null, drop, ground = null_rule(analysis, A)
    d_values = _leaf_values(analysis, A, ground)
    blocks = _blocks(analysis, A.data[analysis.lay.d_src])
    leaf_inv, shift, count = _spd_inverse(_blocks(analysis, d_values))
    note = f"{count} leaf block(s) shifted by {shift:g} x row-sum bound" if count else ""
    return data, A_csr, blocks, d_values, drop, leaf_inv, note, int(null.sum())


def _check_kind(coarse, rank, basis):
    if coarse not in COARSE_KINDS:
        raise ValueError(f"unknown coarse kind {coarse!r}; expected one of {', '.join(COARSE_KINDS)}")
    if coarse == "eig" and (isinstance(rank, bool) or not isinstance(rank, numbers.Integral) or rank < 1):
        raise ValueError(f"rank must be a positive integer, got {rank!r}")
    if (coarse in ("given", "seeded")) != (basis is not None):
        raise ValueError("a basis is needed for coarse='given' or 'seeded' and only for them")


def coarse_space(analysis: TwoLevelAnalysis, A, coarse="eig", rank=4, basis=None) -> torch.Tensor:
    """The coarse basis P alone, (K, Lmax, r) in the padded leaf layout, dropped columns zero.

    Parameters as in :func:`factor`.
    """
    _check_kind(coarse, rank, basis)
    A = check_square(A)
    checked_values(analysis, A)
    null, drop, ground = null_rule(analysis, A)
    P = _coarse_basis(analysis, A, _leaf_values(analysis, A, ground), coarse, rank, basis)
    return dropped_columns(analysis, P, drop).to(analysis.device)


def factor(analysis: TwoLevelAnalysis, A, coarse="eig", rank=4, basis=None) -> BatchedTwoLevel:
    """Per-values setup: leaf inverses, coarse space, Galerkin coarse operator and its inverse.

    Parameters
    ----------
    analysis : TwoLevelAnalysis
        From :func:`analyse` on a matrix with A's pattern and entry order.
    A : scipy.sparse matrix
        The values to factor.
    coarse : {'const', 'eig', 'given', 'seeded'}
        The constant of each piece of each leaf; those and ``rank - 1`` approximate low local Neumann
        eigenvectors per leaf (one inverse-iteration step from smooth seeds); ``basis`` as given (made
        orthonormal, with the constants); or the same step from ``basis`` ('seeded': HTPPC's learned space).
    rank : int
        Vectors per leaf for 'eig' (ignored otherwise).
    basis : array_like or Tensor, shape (K, Lmax, r), optional
        The vectors for 'given' and 'seeded', in padded leaf layout, zero on the padding.
    """
    _check_kind(coarse, rank, basis)
    device = analysis.device
    times = {}
    t0 = time.perf_counter()
    A = check_square(A)
    data, A_csr, blocks, d_values, drop, leaf_inv, leaf_note, n_null = leaf_stage(analysis, A)
    times["leaf"] = _ms(t0, device)
    t0 = time.perf_counter()
    P = dropped_columns(analysis, _coarse_basis(analysis, A, d_values, coarse, rank, basis), drop).to(device)
    limit = max_coarse(device)
    if P.shape[0] * P.shape[2] > limit:
        raise ValueError(f"coarse size K r = {P.shape[0]} x {P.shape[2]} exceeds {limit} "
                         "(dense coarse operator); use larger leaves or a smaller rank")
    times["coarse_space"] = _ms(t0, device)
    t0 = time.perf_counter()
    coarse_inv, shift, _ = _spd_inverse(lifted(galerkin(analysis, blocks, data, P))[None])
    coarse_note = f"Cholesky failed: shifted by {shift:g} x row-sum bound" if shift else ""
    times["coarse_operator"] = _ms(t0, device)
    return BatchedTwoLevel(analysis, A_csr, leaf_inv, P, coarse_inv[0], coarse, (coarse_note, leaf_note), n_null, times)
