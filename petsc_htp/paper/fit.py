"""Structure check (``petsc-htp fit``): fit one frame's packed factors directly, no network.

It measures how many PCG iterations the HTP structure itself can reach on a
frame, separately from how well the network learns to produce it.
"""
from __future__ import annotations

import time

import numpy as np
import torch

from .apply import Factors, HTPOperator, htp_apply
from .partition import build_partition
from ..training.loss import cosine_loss, n_probes, smoothed_probes
from ..training.pcg import pcg
from .train import make_context


def init_factors(part, inv_diag: torch.Tensor, scale: float, seed: int = 0) -> torch.Tensor:
    """Jacobi-like starting point: g = D^-1, small random F, bridges and couplings."""
    gen = torch.Generator().manual_seed(seed)
    packed = torch.randn(part.packed_width, generator=gen) * 0.05 / scale ** 0.5
    f = Factors.unpack(packed, part)
    mask = inv_diag > 0
    f.F.mul_(mask.view(part.n_leaves, part.leaf, 1))
    f.U.mul_(scale ** 0.5 * mask.view(part.n_leaves, part.leaf, 1))
    f.V.mul_(scale ** 0.5 * mask.view(part.n_leaves, part.leaf, 1))
    f.g.copy_(inv_diag)
    return packed


def fit_frame(frame, leaf=128, coarse=32, steps=500, lr=1e-2, seed=0, log=None) -> dict:
    """Optimise the packed factors of one frame with the cosine loss.

    Returns
    -------
    dict with the final loss, PCG iterations of the fitted M, Jacobi's iterations,
    steps and wall time.
    """
    part = build_partition(frame.n, leaf, coarse)
    ctx = make_context(frame.A, part)
    packed = init_factors(part, ctx.inp.inv_diag, ctx.inp.scale, seed).requires_grad_(True)
    mask = ctx.inp.mask.float()
    opt = torch.optim.Adam([packed], lr=lr / ctx.inp.scale ** 0.5)
    t0 = time.perf_counter()
    gen = torch.Generator().manual_seed(seed)
    for step in range(1, steps + 1):
        f = Factors.unpack(packed, part)
        Z = smoothed_probes(ctx.A, ctx.inp.inv_diag, ctx.inp.mask, n_probes(part.n), generator=gen)
        loss = cosine_loss(Z, ctx.A @ Z, lambda X: htp_apply(f, ctx.tree, X * mask[:, None]) * mask[:, None])
        opt.zero_grad()
        loss.backward()
        opt.step()
        if log and step % max(1, steps // 10) == 0:
            log(f"step {step} loss {float(loss):.5f}")
    op = HTPOperator(packed.detach().float(), part)
    res = pcg(frame.A, frame.b, op.apply, maxiter=10 * frame.n)
    jac = pcg(frame.A, frame.b, lambda r: r / frame.A.diagonal(), maxiter=10 * frame.n)
    return {"n": frame.n, "loss": float(loss), "iterations": res.iterations, "reason": res.reason,
            "jacobi_iterations": jac.iterations, "steps": steps, "wall_s": round(time.perf_counter() - t0, 1),
            "ratio_vs_jacobi": res.iterations / max(jac.iterations, 1), "factor_norm": float(np.linalg.norm(
                packed.detach().numpy()))}
