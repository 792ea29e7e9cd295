"""The HTP network: encoder, diagonal and off-diagonal attention stacks, highways, heads.

Maps a :class:`~petsc_htp.paper.features.ModelInput` to one packed factor tensor of
width P that :mod:`petsc_htp.paper.apply` consumes.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import torch
import torch.nn.functional as Fn
from torch import nn

from .features import GLOBAL_FEATURES, NODE_FEATURES, PAIR_FEATURES, ModelInput, strip_tokens
from .partition import Partition, build_partition


@dataclass(frozen=True)
class HTPConfig:
    """Network hyper-parameters (stored with the weights)."""

    d: int = 128
    n_layers: int = 3
    leaf: int = 128
    p_off: int = 4
    n_gcn: int = 2
    heads: int = 8
    highways: bool = True
    bias_hidden: int = 16
    shift: bool = False

    @property
    def coarse(self) -> int:
        """L_s = L / p_off."""
        return self.leaf // self.p_off

    def validate(self) -> "HTPConfig":
        """Raise ValueError on inconsistent settings."""
        if self.leaf % self.p_off:
            raise ValueError(f"p_off={self.p_off} must divide L={self.leaf}")
        if self.d % self.heads:
            raise ValueError(f"heads={self.heads} must divide d={self.d}")
        if min(self.d, self.n_layers, self.leaf, self.p_off, self.heads, self.bias_hidden) < 1 or self.n_gcn < 0:
            raise ValueError(f"invalid configuration {self}")
        return self

    def to_dict(self) -> dict:
        """Plain dict for checkpoints."""
        return asdict(self)

    def partition(self, n: int) -> Partition:
        """The cached partition this configuration uses for N indices."""
        return build_partition(n, self.leaf, self.coarse)


def _mlp(i, h, o):
    return nn.Sequential(nn.Linear(i, h), nn.GELU(), nn.Linear(h, o))


class GCNLayer(nn.Module):
    """Residual graph convolution with D^-1 |A_off| messages."""

    def __init__(self, d):
        super().__init__()
        self.norm = nn.LayerNorm(d)
        self.mix = _mlp(2 * d, d, d)

    def forward(self, h, message):
        z = self.norm(h)
        return h + self.mix(torch.cat([z, message @ z], dim=1))


class Block(nn.Module):
    """Pre-norm transformer block with a pair-descriptor attention bias.

    ``attend`` and ``feed`` are separate so the highway exchange can sit between them.
    """

    def __init__(self, cfg: HTPConfig):
        super().__init__()
        d, self.heads = cfg.d, cfg.heads
        self.norm1 = nn.LayerNorm(d)
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)
        self.bias = _mlp(PAIR_FEATURES, cfg.bias_hidden, cfg.heads)
        width = 4 * d if cfg.highways else d
        self.norm2 = nn.LayerNorm(width)
        self.ffn = _mlp(width, 4 * d, d)

    def attend(self, x, pair, key_mask):
        B, T, d = x.shape
        q, k, v = self.qkv(self.norm1(x)).view(B, T, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        bias = self.bias(pair).permute(0, 3, 1, 2)
        bias = bias.masked_fill(~key_mask[:, None, None, :], float("-inf"))
        att = Fn.scaled_dot_product_attention(q, k, v, attn_mask=bias)
        return x + self.out(att.transpose(1, 2).reshape(B, T, d))

    def feed(self, x, context=None):
        z = x if context is None else torch.cat([x, context], dim=-1)
        return x + self.ffn(self.norm2(z))


@lru_cache(maxsize=64)
def _strip_ranges(part: Partition, device: str) -> torch.Tensor:
    """Sub-strip node ranges on a device, cached so forward passes do no host-to-device copies."""
    return torch.as_tensor(strip_tokens(part), device=device)


class Highways:
    """Row, column and global buffers shared by both stacks (means, not sums)."""

    def __init__(self, part: Partition, mask: torch.Tensor, tile_mask: torch.Tensor):
        dev = mask.device
        ranges = _strip_ranges(part, str(dev))                          # (M, 2, Ls, 2)
        self.n_pad = part.n_pad
        self.start, self.stop = ranges[..., 0], ranges[..., 1]
        self.mask = mask.float()[:, None]
        self.tile_mask = tile_mask[:, 1].float()[..., None]      # a token is real if its column part is
        self.count = self.mask.sum() + self.tile_mask.sum()
        ones = torch.ones(*ranges.shape[:-1], 1, device=dev)
        self.row_count = (self.mask + self._spread(ones[:, 0], 0)).clamp(min=1)
        self.col_count = (self.mask + self._spread(ones[:, 1], 1)).clamp(min=1)
        real = torch.cat([torch.zeros(1, 1, device=dev), torch.cumsum(self.mask, 0)])
        self.tok_count = (real[self.stop] - real[self.start]).clamp(min=1)

    def _spread(self, tok, side):
        """Add each tile token to every node of its sub-strip (difference array + cumsum)."""
        diff = tok.new_zeros(self.n_pad + 1, tok.shape[-1])
        diff = diff.index_add(0, self.start[:, side].reshape(-1), tok.reshape(-1, tok.shape[-1]))
        diff = diff.index_add(0, self.stop[:, side].reshape(-1), -tok.reshape(-1, tok.shape[-1]))
        return torch.cumsum(diff, 0)[:-1]

    def _pool(self, x, side):
        """Mean of node values over every tile token's sub-strip (real nodes only)."""
        c = torch.cat([x.new_zeros(1, x.shape[-1]), torch.cumsum(x * self.mask, 0)])
        return c[self.stop[:, side]] - c[self.start[:, side]]

    def pool(self, x, side):
        """Real-node mean of ``x`` (N_pad, d) over each tile's row (0) or column (1) tokens."""
        return self._pool(x, side) / self.tok_count[:, side]

    def exchange(self, xd, xo):
        """Return FFN contexts [row, column, global] for diagonal and tile tokens."""
        d = xd.shape[-1]
        flat = xd.reshape(-1, d) * self.mask
        xo_m = xo * self.tile_mask
        row = (flat + self._spread(xo_m, 0)) / self.row_count
        col = (flat + self._spread(xo_m, 1)) / self.col_count
        glob = (flat.sum(0) + xo_m.sum((0, 1))) / self.count
        ctx_d = torch.cat([row, col, glob.expand_as(row)], dim=1).view(*xd.shape[:-1], 3 * d)
        ctx_o = torch.cat([self.pool(row, 0), self.pool(col, 1), glob.expand(*xo.shape)], dim=-1)
        return ctx_d, ctx_o


class HTPNet(nn.Module):
    """Hierarchical Transformer Preconditioner network.

    Additions to the paper's design: a learned embedding of each token's slot within its
    leaf (and strip); an MLP of its position relative to the leaf's centroid (zero without
    geometry; zero-initialised, so a warm start from weights without it keeps their M);
    factor rows emitted for D^-1/2 A D^-1/2 and scaled back (M = D^-1/2 M^ D^-1/2).
    """

    def __init__(self, cfg: HTPConfig = HTPConfig()):
        super().__init__()
        self.cfg = cfg.validate()
        d, L, Ls = cfg.d, cfg.leaf, cfg.coarse
        self.embed = _mlp(NODE_FEATURES + GLOBAL_FEATURES, d, d)
        self.gcn = nn.ModuleList(GCNLayer(d) for _ in range(cfg.n_gcn))
        self.row_in = nn.Linear(d, d)
        self.col_in = nn.Linear(d, d)
        self.diag = nn.ModuleList(Block(cfg) for _ in range(cfg.n_layers))
        self.off = nn.ModuleList(Block(cfg) for _ in range(cfg.n_layers))
        self.norm_d = nn.LayerNorm(d)
        self.norm_o = nn.LayerNorm(d)
        self.leaf_head = _mlp(d, d, L)
        self.u_head = nn.Linear(d, Ls)
        self.v_head = nn.Linear(d, Ls)
        self.bridge_u = nn.Linear(d, Ls)
        self.bridge_v = nn.Linear(d, Ls)
        self.gate = nn.Linear(d, 1)
        self.shift = nn.Parameter(torch.tensor(-6.0)) if cfg.shift else None
        self.slot = nn.Parameter(0.02 * torch.randn(L, d))        # within-leaf position of a token
        self.leaf_pos = _mlp(2, d, d)                              # geometric position within its leaf
        nn.init.zeros_(self.leaf_pos[-1].weight)
        nn.init.zeros_(self.leaf_pos[-1].bias)
        self.coarse_slot = nn.Parameter(0.02 * torch.randn(Ls, d))
        # Start near Jacobi + F F^T (PSD): B = U V^T is zero at first, yet U gets gradients through V.
        for head, std in ((self.leaf_head[-1], 0.3), (self.bridge_u, 0.3), (self.bridge_v, 0.3), (self.v_head, 0.3),
                          (self.u_head, 0.0), (self.gate, 0.02)):
            nn.init.normal_(head.weight, std=std / head.in_features ** 0.5)
            nn.init.zeros_(head.bias)
        nn.init.constant_(self.gate.bias, 0.5413)   # softplus(0.5413) = 1: the gate starts as Jacobi

    def n_params(self) -> int:
        """Number of trainable parameters (independent of N)."""
        return sum(p.numel() for p in self.parameters())

    def forward(self, inp: ModelInput, part: Partition) -> torch.Tensor:
        """Return the packed (P,) factor tensor for one operator."""
        cfg = self.cfg
        K, L, Ls, M = part.n_leaves, part.leaf, part.coarse, part.n_tiles
        if L != cfg.leaf or Ls != cfg.coarse:
            raise ValueError(f"partition (L={L}, L_s={Ls}) does not match the model (L={cfg.leaf}, L_s={cfg.coarse})")
        mask = inp.mask
        x = torch.cat([inp.node, inp.glob.expand(inp.node.shape[0], -1)], dim=1)
        h = self.embed(x) * mask[:, None]
        for layer in self.gcn:
            h = layer(h, inp.message) * mask[:, None]
        hw = Highways(part, mask, inp.tile_mask)
        xd = (h + self.leaf_pos(inp.leaf_xy) * mask[:, None]).view(K, L, -1) + self.slot
        xo = self.row_in(hw.pool(h, 0)) + self.col_in(hw.pool(h, 1)) + self.coarse_slot   # (M, Ls, d)
        dmask = mask.view(K, L)
        omask = inp.tile_mask[:, 1]
        for bd, bo in zip(self.diag, self.off):
            xd = bd.attend(xd, inp.diag_pair, dmask)
            if M:
                xo = bo.attend(xo, inp.tile_pair, omask)
            ctx_d, ctx_o = hw.exchange(xd, xo) if cfg.highways else (None, None)
            xd = bd.feed(xd, ctx_d)
            if M:
                xo = bo.feed(xo, ctx_o)
        zd = self.norm_d(xd) * dmask[..., None]
        zo = self.norm_o(xo)
        # Rows are emitted for the unit-free D^-1/2 A D^-1/2 and scaled back: M = D^-1/2 M^ D^-1/2.
        rs = inp.inv_diag.sqrt().view(K, L, 1)
        F = self.leaf_head(zd) * rs                                             # (K, L, L)
        B = torch.bmm(self.u_head(zo), self.v_head(zo).transpose(1, 2))         # (M, Ls, Ls)
        U = self.bridge_u(zd) * rs
        V = self.bridge_v(zd) * rs
        lam = Fn.softplus(self.gate(zd)).reshape(-1)
        if self.shift is not None:
            lam = lam + Fn.softplus(self.shift)
        g = lam * inp.inv_diag
        return torch.cat([F.reshape(-1), B.reshape(-1), U.reshape(-1), V.reshape(-1), g])
