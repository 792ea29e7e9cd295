"""End-to-end training of the coarse-basis network (``python -m petsc_htp.twolevel.coarsetrain``).

The loss is the cosine-Hutchinson loss of the two-level M built from the network's basis,
with gradients through the exact Galerkin coarse solve; the leaf inverses are fixed per
frame. Frames are Morton-ordered with coordinates and density, and a fraction are randomly
permuted bare matrices on METIS leaves. AdamW, linear warm-up then cosine decay over the
time budget, a JSONL log, atomic checkpoints (``last.pt``, ``best.pt`` by held-out PCG
iterations, ``final.pt``).
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import random
import sys
import time
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch

from . import coarsenet
from .coarsenet import CoarseConfig, CoarseInput, CoarseNet, coarse_input
from ..scenes.dataset import load_dataset
from .leaves import choose_leaves
from ..training.loss import cosine_loss, n_probes, smoothed_probes
from ..training.pcg import pcg
from .batched import TwoLevelAnalysis, dropped_columns, analyse, factor, galerkin, leaf_stage, lifted, null_rule
from .coarsespace import without

PROBE_STEPS = 30            # probe smoothing steps (see context_loss)


@dataclass
class Context:
    """One training operator: analysis, fixed two-level pieces and the network input."""

    analysis: TwoLevelAnalysis
    data: torch.Tensor          # A.data, float64
    A: torch.Tensor             # padded permuted A, sparse CSR float64
    blocks: torch.Tensor        # (K, Lmax, Lmax) leaf blocks
    leaf_inv: torch.Tensor      # (K, Lmax, Lmax) inverses of the (grounded) leaf blocks
    drop: np.ndarray            # pieces whose constant the coarse space leaves out
    null_rows: torch.Tensor     # padded rows of the null components and each one's component
    null_label: torch.Tensor
    inp: CoarseInput


def make_context(cfg: CoarseConfig, A, leaves, coords=None, density=None, device="cpu") -> Context:
    """Precompute everything but the coarse basis for one operator on one leaf layout."""
    an = analyse(A, leaves, device)
    data, A_t, blocks, _, drop, leaf_inv, _, _ = leaf_stage(an, A)
    lay = an.lay
    null, _, _ = null_rule(an, A)
    rows = np.flatnonzero(null[an.comp_of_row])                       # A's rows in null components
    return Context(an, data, A_t, blocks, leaf_inv, drop, torch.as_tensor(lay.pos[lay.iperm[rows]]),
                   torch.as_tensor(an.comp_of_row[rows]), coarse_input(cfg, an, A, coords, density))


def coarse_vectors(ctx: Context, X: torch.Tensor) -> torch.Tensor:
    """The coarse space of the network's vectors X (K, Lmax, q), differentiably, as the two-level method
    builds it (:func:`petsc_htp.twolevel.coarsespace.basis`): X made orthogonal to the pieces' constants and
    orthonormal (by QR, whose gradient is stable where the Gram eigendecomposition's is not), then the
    constants, the dropped pieces' zeroed."""
    constants = ctx.analysis.constants
    P = torch.cat([torch.linalg.qr(without(X.to(torch.float64), constants))[0], constants], dim=2)
    return dropped_columns(ctx.analysis, P, ctx.drop)


def null_projector(ctx: Context):
    """X -> X minus its mean over each null component (identity when A is regular)."""
    rows, label = ctx.null_rows, ctx.null_label
    if rows.numel() == 0:
        return lambda X: X
    size = torch.bincount(label).to(torch.float64)[:, None]

    def project(X):
        mean = torch.zeros(size.shape[0], X.shape[1], dtype=X.dtype, device=X.device)
        mean = mean.index_add(0, label, X[rows]) / size.clamp_min(1)
        return X.index_add(0, rows, -mean[label])
    return project


def two_level_apply(ctx: Context, P: torch.Tensor):
    """Differentiable X -> M X for padded blocks X (K Lmax, k), P the coarse space (K, Lmax, r).

    A_c = P^T A P with its unused columns lifted as :func:`twolevel.batched.factor` does; the lift
    is held fixed, so gradients are exact.
    """
    an = ctx.analysis
    K, L = an.shape
    r = P.shape[2]
    chol = torch.linalg.cholesky(lifted(galerkin(an, ctx.blocks, ctx.data, P)))

    def coarse(X):
        y = torch.cholesky_solve((P.mT @ X.view(K, L, -1)).reshape(K * r, -1), chol)
        return (P @ y.view(K, r, -1)).reshape(K * L, -1)

    def apply(R):
        v = torch.bmm(ctx.leaf_inv, (R - ctx.A @ coarse(R)).view(K, L, -1)).reshape(K * L, -1)
        return v + coarse(R - ctx.A @ v)
    return apply


def context_loss(net: CoarseNet, ctx: Context, generator=None, probe_steps=PROBE_STEPS) -> torch.Tensor:
    """Cosine-Hutchinson loss of the two-level M on fresh smoothed probes (null space removed).

    ``probe_steps`` Jacobi steps put the probes' energy on the low modes that the coarse space
    serves (2 steps, the fine-level default, rank bases against their CG iterations poorly).
    """
    mask = ctx.analysis.mask.reshape(-1)
    A32 = ctx.A.to(torch.float32)
    inv_diag = torch.where(mask > 0, 1.0 / ctx.blocks.diagonal(dim1=1, dim2=2).reshape(-1), 0.0)
    Z = smoothed_probes(A32, inv_diag.float(), mask > 0, n_probes(ctx.analysis.n),
                        steps=probe_steps, generator=generator)
    project = null_projector(ctx)
    Z = project(Z.double())
    apply = two_level_apply(ctx, coarse_vectors(ctx, coarsenet.own_vectors(net, net(ctx.inp))))
    return cosine_loss(Z, (ctx.A @ Z).detach(), lambda X: project(apply(X)))


@dataclass
class TrainSettings:
    """Everything about a run except the network configuration."""

    scales: tuple = (1024, 2048, 4096)
    frames: int = 24
    val_frames: int = 2
    probe_steps: int = PROBE_STEPS
    geometry_free: float = 0.5
    lr: float = 3e-3
    warmup: int = 50
    weight_decay: float = 1e-4
    clip: float = 1.0
    max_steps: int = 100_000
    max_minutes: float = 30.0
    eval_every: int = 100
    log_every: int = 10
    seed: int = 0
    threads: int = 1
    out: str = "runs/coarse"
    cache_dir: str = ""


def frame_contexts(cfg, frames, bare: bool, seed: int) -> list:
    """Contexts of frames: Morton leaves with geometry, or permuted bare matrices on METIS leaves."""
    out = []
    for i, fr in enumerate(frames):
        if bare:
            q = np.random.default_rng(seed + i).permutation(fr.n)
            A = sp.csr_matrix(fr.A[q][:, q])
            out.append((make_context(cfg, A, choose_leaves(A)), A, fr.b[q]))
        else:
            lv = choose_leaves(fr.A, fr.coords)
            out.append((make_context(cfg, fr.A, lv, fr.coords, fr.rho), fr.A, fr.b))
    return out


def evaluate(net: CoarseNet, val: list, probe_steps=PROBE_STEPS) -> dict:
    """PCG iterations (rtol 1e-8) and a fixed-probe loss on held-out contexts."""
    net.eval()
    its, losses = [], []
    for ctx, A, b in val:
        with torch.no_grad():
            losses.append(float(context_loss(net, ctx, torch.Generator().manual_seed(1234), probe_steps)))
            basis = coarsenet.own_vectors(net, net(ctx.inp)).double()
        pre = factor(ctx.analysis, A, coarse="given", basis=basis)
        its.append(pcg(A, b, pre.apply, 1e-8).iterations)
    net.train()
    return {"val_iters": its, "val_iters_sum": int(sum(its)), "val_loss": float(np.mean(losses))}


def learning_rate(s: TrainSettings, step: int, frac: float) -> float:
    """Linear warm-up over ``s.warmup`` steps, then cosine decay over the time budget."""
    warm = min(1.0, (step + 1) / max(1, s.warmup))
    return s.lr * warm * 0.5 * (1.0 + math.cos(math.pi * min(frac, 1.0)))


def training_contexts(cfg: CoarseConfig, s: TrainSettings) -> tuple:
    """(geometry contexts, bare contexts, validation contexts); validation at the largest scale."""
    geo, bare, val = [], [], []
    for n in s.scales:
        frames = load_dataset(n, "train", count=s.frames + s.val_frames, cache_dir=s.cache_dir or None)
        geo += frame_contexts(cfg, frames[:s.frames], False, s.seed)
        bare += frame_contexts(cfg, frames[:s.frames], True, s.seed + 10_000)
        if n == max(s.scales):
            held = frames[s.frames:]
            val = frame_contexts(cfg, held, False, 0) + frame_contexts(cfg, held, True, 20_000)
    return geo, bare, val


def train(cfg: CoarseConfig, s: TrainSettings, command: str = "") -> Path:
    """Train a coarse network; returns the path of the best checkpoint (``out/best.pt``)."""
    torch.set_num_threads(s.threads)
    torch.manual_seed(s.seed)
    rng = random.Random(s.seed)
    gen = torch.Generator().manual_seed(s.seed)
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    geo, bare, val = training_contexts(cfg, s)
    net = CoarseNet(cfg)
    opt = torch.optim.AdamW(net.parameters(), lr=s.lr, weight_decay=s.weight_decay)
    prov = {"command": command, "settings": {f.name: getattr(s, f.name) for f in fields(s)},
            "parameters": net.n_parameters(), "torch": str(torch.__version__),
            "python": platform.python_version(), "machine": platform.platform(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    minutes = lambda: (time.perf_counter() - t_start) / 60  # noqa: E731
    best, step, t0 = None, 0, time.perf_counter()
    budget = s.max_minutes * 60.0 - (t0 - t_start)
    with open(out / "train_log.jsonl", "a") as log:
        def record(**row):
            log.write(json.dumps({"step": step, "minutes": minutes(), **row}) + "\n")
            log.flush()

        while True:
            frac = (time.perf_counter() - t0) / budget
            done = step >= s.max_steps or frac >= 1.0
            if step % s.eval_every == 0 or done:
                ev = evaluate(net, val, s.probe_steps)
                record(**ev)
                if best is None or (ev["val_iters_sum"], ev["val_loss"]) < best:
                    best = (ev["val_iters_sum"], ev["val_loss"])
                    coarsenet.save(out / "best.pt", net, {**prov, "steps": step, **ev})
                coarsenet.save(out / "last.pt", net, {**prov, "steps": step}, extra={"optimizer": opt.state_dict()})
            if done:
                break
            is_bare = rng.random() < s.geometry_free
            ctx, _, _ = rng.choice(bare if is_bare else geo)
            lr = learning_rate(s, step, frac)
            for group in opt.param_groups:
                group["lr"] = lr
            try:
                loss = context_loss(net, ctx, gen, s.probe_steps)
            except torch.linalg.LinAlgError:      # a rank-deficient basis: skip the step
                record(skipped="coarse Cholesky failed")
                step += 1
                continue
            opt.zero_grad(set_to_none=True)
            loss.backward()
            gnorm = float(torch.nn.utils.clip_grad_norm_(net.parameters(), s.clip))
            opt.step()
            if step % s.log_every == 0:
                record(loss=loss.item(), lr=lr, grad_norm=gnorm, n=ctx.analysis.n, bare=is_bare)
            step += 1
    coarsenet.save(out / "final.pt", net, {**prov, "steps": step, "train_minutes": minutes(), **ev})
    return out / "best.pt"


def main(argv=None) -> int:
    """Command line: ``python -m petsc_htp.twolevel.coarsetrain --rank 4 --max-minutes 30 --out runs/coarse``."""
    p = argparse.ArgumentParser(prog="python -m petsc_htp.twolevel.coarsetrain", description=__doc__.split("\n")[0])
    for f in fields(CoarseConfig):
        flag = "--" + f.name.replace("_", "-")
        if f.type in ("bool", bool):
            p.add_argument(flag, type=lambda v: v.lower() in ("1", "true", "yes"), default=f.default)
        else:
            p.add_argument(flag, type=type(f.default), default=f.default)
    for f in fields(TrainSettings):
        flag = "--" + f.name.replace("_", "-")
        if f.name == "scales":
            p.add_argument(flag, type=int, nargs="+", default=list(f.default))
        else:
            p.add_argument(flag, type=type(f.default), default=f.default)
    a = vars(p.parse_args(argv))
    cfg = CoarseConfig(**{f.name: a[f.name] for f in fields(CoarseConfig)})
    s = TrainSettings(**{f.name: a[f.name] for f in fields(TrainSettings)})
    s.scales = tuple(s.scales)
    args = sys.argv[1:] if argv is None else list(argv)
    best = train(cfg, s, " ".join(["python -m petsc_htp.twolevel.coarsetrain", *args]))
    print(f"best checkpoint: {best}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
