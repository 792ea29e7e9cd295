"""A small network that emits the coarse basis of the two-level preconditioner.

For every leaf of a :class:`~petsc_htp.twolevel.TwoLevelAnalysis` the network reads the
operator (and, when given, coordinates and density) and returns r vectors: the leaf
constant plus r - 1 learned vectors, smoothed by a few damped-Jacobi steps with the leaf's
Neumann matrix. Features are ratios of A's entries, so the basis is invariant to A -> c A.
Use it with ``twolevel.factor(analysis, A, coarse="seeded", basis=learned_vectors(...))`` (as
HTPPC does: the vectors refined by one inverse-iteration step) or ``coarse="given"`` (raw, as trained).
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch
from torch import nn

from ..training import checkpoint
from ..training.checkpoint import CheckpointError
from .batched import checked_values

FORMAT = "petsc_htp-coarse-checkpoint"
VERSION = 1
DEFAULT = Path(__file__).parent.parent / "checkpoints" / "coarse_default.pt"
NODE_FEATURES = 10          # plus CoarseConfig.noise_channels
NOISE_SEED = 0              # fixed: the smoothed-noise positions are deterministic
FLOAT = torch.float32


@dataclass(frozen=True)
class CoarseConfig:
    """Network configuration (stored with the weights).

    Attributes
    ----------
    rank : int
        Vectors per leaf r (the first is the leaf constant when ``const_column``).
    width, heads : int
        Token width d and attention heads.
    gcn_layers, attn_layers : int
        Graph-convolution layers on D^-1 |A_off| (whole matrix) and transformer layers
        within each leaf.
    noise_channels, feature_smoothing : int
        Geometry-free position features: Gaussian vectors (fixed seed) after this many
        Jacobi steps with the leaf Neumann matrix, normalised per leaf.
    output_smoothing : int
        Jacobi steps applied to the network's vectors.
    omega : float
        Jacobi damping.
    const_column : bool
        Put the leaf constant first and learn r - 1 vectors.
    """

    rank: int = 4
    width: int = 32
    heads: int = 2
    gcn_layers: int = 2
    attn_layers: int = 1
    noise_channels: int = 8
    feature_smoothing: int = 40
    output_smoothing: int = 8
    omega: float = 0.6
    const_column: bool = True

    def __post_init__(self):
        if self.rank < 1 + self.const_column or self.width % self.heads:
            raise ValueError(f"invalid coarse network configuration {self}")

    def to_dict(self) -> dict:
        """Plain dict for the checkpoint."""
        return asdict(self)


@dataclass
class CoarseInput:
    """What the network reads for one operator on one leaf layout (padded, float32).

    Attributes
    ----------
    node : Tensor (K, Lmax, F)
    bias : Tensor (K, Lmax, Lmax)
        |A_ij| / sqrt(A_ii A_jj) within each leaf, zero on the diagonal.
    message : sparse Tensor (K Lmax, K Lmax)
        D^-1 |A_off| over the whole matrix.
    smoother : sparse Tensor (K Lmax, K Lmax)
        Jacobi iteration matrix I - omega D^-1 S, S the leaf Neumann matrices (block diagonal).
    mask : Tensor (K, Lmax)
        1.0 on real rows.
    """

    node: torch.Tensor
    bias: torch.Tensor
    message: torch.Tensor
    smoother: torch.Tensor
    mask: torch.Tensor


def _csr(analysis, vals):
    """Float32 sparse CSR tensor with the analysed padded pattern and per-entry ``vals``."""
    n_pad = analysis.mask.numel()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)      # "sparse CSR support is in beta"
        return torch.sparse_csr_tensor(analysis.crow, analysis.col, vals.to(FLOAT),
                                       size=(n_pad, n_pad), check_invariants=False)


def _leaf_normalise(X, mask):
    """Per leaf and channel: remove the mean over real rows and divide by the RMS."""
    m = mask[:, :, None]
    count = m.sum(1, keepdim=True)
    X = (X - (X * m).sum(1, keepdim=True) / count) * m
    return X / ((X.square().sum(1, keepdim=True) / count).sqrt() + 1e-12)


def _padded(analysis, values):
    """Caller-order rows (N, c) as a padded (K, Lmax, c) float64 tensor."""
    K, L = analysis.shape
    values = np.asarray(values, dtype=np.float64).reshape(analysis.n, -1)
    out = torch.zeros(K * L, values.shape[1], dtype=torch.float64, device=analysis.device)
    out[analysis.pos] = torch.as_tensor(values[analysis.leaves.perm], device=analysis.device)
    return out.view(K, L, -1)


def smooth(smoother, X, steps):
    """``steps`` damped-Jacobi steps X <- (I - omega D^-1 S) X, X of shape (K, Lmax, c)."""
    shape = X.shape
    X = X.reshape(-1, shape[-1])
    for _ in range(steps):
        X = smoother @ X
    return X.reshape(shape)


def coarse_input(cfg: CoarseConfig, analysis, A, coords=None, density=None) -> CoarseInput:
    """Network input from A's values on the analysed layout.

    Node features, all invariant to A -> c A: log(A_ii / mean A_jj); the sum, minimum and
    maximum of A_ij / A_ii over j != i; degree / mean degree; whether the row couples out
    of its leaf and the sum of those couplings / A_ii; coordinates relative to the leaf's
    centroid over its RMS radius and log density minus its mean (zero when not given);
    ``cfg.noise_channels`` smoothed-noise channels.

    Parameters
    ----------
    cfg : CoarseConfig
    analysis : TwoLevelAnalysis
    A : scipy.sparse matrix
        Values with the analysed pattern.
    coords : array_like (N, 2), optional
    density : array_like (N,), optional
        Both in A's row order.
    """
    K, L = analysis.shape
    n_pad, dev = K * L, analysis.device
    data = checked_values(analysis, A)
    vals, cols = data[analysis.csr_src], analysis.col
    rows = torch.repeat_interleave(torch.arange(n_pad, device=dev), analysis.crow.diff())
    mask = analysis.mask.reshape(-1)
    on = rows == cols
    d = torch.zeros(n_pad, dtype=vals.dtype, device=dev).index_add_(0, rows[on], vals[on])
    if (d[mask > 0] <= 0).any():
        raise ValueError("A has non-positive diagonal entries; the coarse network needs an SPD matrix")
    d = torch.where(mask > 0, d, 1.0)
    v = torch.where(on, 0.0, vals / d[rows])
    inside = (rows // L == cols // L) & ~on
    leaves_row = (~inside & ~on).to(v.dtype)
    zeros = torch.zeros(n_pad, dtype=vals.dtype, device=dev)
    deg = zeros.index_add(0, rows, (~on).to(v.dtype))
    leave = zeros.index_add(0, rows, v * leaves_row)
    r, off = rows[~on], v[~on]
    stats = [torch.log(d / d[mask > 0].mean()), zeros.index_add(0, rows, v),
             zeros.scatter_reduce(0, r, off, "amin", include_self=False),
             zeros.scatter_reduce(0, r, off, "amax", include_self=False),
             deg / deg[mask > 0].mean(), (zeros.index_add(0, rows, leaves_row) > 0).to(v.dtype), leave]
    bias = torch.zeros(n_pad * L, dtype=FLOAT, device=dev)
    bias[(rows * L + cols % L)[inside]] = (vals[inside].abs() / (d[rows] * d[cols])[inside].sqrt()).to(FLOAT)
    jacobi = torch.where(on, 1.0 - cfg.omega * (1.0 + leave[rows]), torch.where(inside, -cfg.omega * v, 0.0))
    smoother = _csr(analysis, torch.where(mask[rows] > 0, jacobi, 0.0))
    gen = torch.Generator().manual_seed(NOISE_SEED)
    noise = torch.randn(n_pad, cfg.noise_channels, generator=gen).to(dev) * mask[:, None].to(FLOAT)
    noise = _leaf_normalise(smooth(smoother, noise.view(K, L, -1), cfg.feature_smoothing), analysis.mask.to(FLOAT))
    m2 = analysis.mask[:, :, None]
    xy = torch.zeros(K, L, 2, dtype=torch.float64, device=dev)
    if coords is not None:
        xy = _padded(analysis, coords)
        xy = (xy - (xy * m2).sum(1, keepdim=True) / m2.sum(1, keepdim=True)) * m2
        xy = xy / ((xy.square().sum((1, 2), keepdim=True) / m2.sum(1, keepdim=True)).sqrt() + 1e-300)
    logrho = torch.zeros(K, L, 1, dtype=torch.float64, device=dev)
    if density is not None:
        logrho = torch.log(_padded(analysis, density).clamp_min(1e-300)) * m2
        logrho = (logrho - logrho.sum() / m2.sum()) * m2
    node = torch.cat([torch.stack(stats, 1).view(K, L, -1), xy, logrho], 2) * m2
    return CoarseInput(torch.cat([node.to(FLOAT), noise], 2), bias.view(K, L, L), _csr(analysis, v.abs()),
                       smoother, analysis.mask.to(FLOAT))


class _AttentionBlock(nn.Module):
    """Pre-norm transformer block within each leaf; attention biased by the leaf's |A_ij|."""

    def __init__(self, d, heads):
        super().__init__()
        self.heads = heads
        self.norm1, self.norm2 = nn.LayerNorm(d), nn.LayerNorm(d)
        self.qkv, self.out = nn.Linear(d, 3 * d), nn.Linear(d, d)
        self.bias_scale = nn.Parameter(torch.ones(heads))
        self.ffn = nn.Sequential(nn.Linear(d, 2 * d), nn.GELU(), nn.Linear(2 * d, d))

    def forward(self, h, bias, mask):
        K, L, d = h.shape
        q, k, v = self.qkv(self.norm1(h)).view(K, L, 3, self.heads, -1).permute(2, 0, 3, 1, 4)
        keys = torch.where(mask > 0, 0.0, float("-inf"))[:, None, None, :]
        att = torch.addcmul(keys, bias[:, None], self.bias_scale[None, :, None, None])
        y = nn.functional.scaled_dot_product_attention(q, k, v, attn_mask=att)
        h = h + self.out(y.transpose(1, 2).reshape(K, L, d))
        return h + self.ffn(self.norm2(h))


class CoarseNet(nn.Module):
    """Operator on a leaf layout -> coarse basis (K, Lmax, r), zero on the padding."""

    def __init__(self, cfg: CoarseConfig):
        super().__init__()
        self.cfg = cfg
        d = cfg.width
        self.embed = nn.Linear(NODE_FEATURES + cfg.noise_channels, d)
        self.gcn = nn.ModuleList(nn.Linear(2 * d, d) for _ in range(cfg.gcn_layers))
        self.attn = nn.ModuleList(_AttentionBlock(d, cfg.heads) for _ in range(cfg.attn_layers))
        self.head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, cfg.rank - cfg.const_column))

    def forward(self, inp: CoarseInput) -> torch.Tensor:
        """Unnormalised basis (K, Lmax, r), float32."""
        K, L, _ = inp.node.shape
        m = inp.mask[:, :, None]
        h = self.embed(inp.node) * m
        for layer in self.gcn:
            flat = h.reshape(K * L, -1)
            h = h + nn.functional.gelu(layer(torch.cat((flat, inp.message @ flat), 1))).view(K, L, -1) * m
        for block in self.attn:
            h = block(h, inp.bias, inp.mask) * m
        X = smooth(inp.smoother, self.head(h) * m, self.cfg.output_smoothing)
        X = _leaf_normalise(X, inp.mask)
        return torch.cat((m, X), 2) if self.cfg.const_column else X

    def n_parameters(self) -> int:
        """Number of weights."""
        return sum(p.numel() for p in self.parameters())


def learned_basis(net: CoarseNet, analysis, A, coords=None, density=None) -> torch.Tensor:
    """The network's coarse basis for ``factor(..., coarse="given", basis=...)``.

    Parameters
    ----------
    net : CoarseNet
    analysis : TwoLevelAnalysis
    A : scipy.sparse matrix
        Values with the analysed pattern.
    coords, density : array_like, optional
        (N, 2) coordinates and (N,) density in A's row order.

    Returns
    -------
    Tensor (K, Lmax, r), float64 on the analysis' device, zero on the padding.
    """
    with torch.inference_mode():
        net = net.to(analysis.device)
        return net(coarse_input(net.cfg, analysis, A, coords, density)).to(torch.float64)


def own_vectors(net: CoarseNet, basis: torch.Tensor) -> torch.Tensor:
    """The network's vectors besides its leaf constant (the coarse space adds every piece's constant itself)."""
    return basis[:, :, 1:] if net.cfg.const_column else basis


def learned_vectors(net: CoarseNet, analysis, A, coords=None, density=None) -> torch.Tensor:
    """:func:`learned_basis` without the leaf constant: the seeds of the two-level 'seeded' coarse space."""
    return own_vectors(net, learned_basis(net, analysis, A, coords, density))


def learned_seeds(net: CoarseNet, analysis, rows, st, coords, density, smooth) -> np.ndarray:
    """The network's vectors (constant column left out) in the leaves' row order as the seeds of the two-level
    method on one rank (:class:`~petsc_htp.twolevel.structure.Structure` ``st``; ``rows``: the rank's rows, whose
    couplings to other ranks are folded into the diagonal), plus the smooth extras (``smooth``) where it keeps
    some."""
    lay = st.lay
    block = st.block
    if st.coll.size > 1:
        outside = np.asarray(rows.sum(axis=1)).ravel() - np.asarray(block.sum(axis=1)).ravel()
        block = (block + sp.diags(outside)).tocsr()
        block.sort_indices()
    P = learned_vectors(net, analysis, block, coords, density).cpu()
    K, L = lay.shape
    out = P.reshape(K * L, -1)[torch.as_tensor(lay.pos)].numpy()
    return np.asfortranarray(np.hstack([out, smooth[:, st.q:]]) if st.extra else out)


def save(path, net: CoarseNet, provenance: dict, extra: dict | None = None) -> Path:
    """Write weights, configuration and provenance atomically (``extra``: resume state)."""
    return checkpoint.save(path, net, provenance, extra, FORMAT, VERSION)


def read(path=None) -> dict:
    """Read and validate a coarse-network checkpoint (the shipped one when ``path`` is None)."""
    return checkpoint.read(path, FORMAT, VERSION, DEFAULT, "petsc_htp coarse-network checkpoint")


def cached(path=None) -> tuple[CoarseNet, dict]:
    """:func:`load` once per process until the file changes; the network is shared (eval mode)."""
    return checkpoint.cached(path, DEFAULT, load)


def load(path=None) -> tuple[CoarseNet, dict]:
    """Return (network in eval mode, provenance) from a checkpoint."""
    obj = read(path)
    try:
        net = CoarseNet(CoarseConfig(**obj["config"]))
        net.load_state_dict(obj["state_dict"])
    except (TypeError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"coarse checkpoint {path} does not match its configuration: {exc}") from exc
    return net.eval(), obj.get("provenance", {})
