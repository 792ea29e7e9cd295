"""Self-supervised training of the HTP network (``petsc-htp train``).

AdamW + ReduceLROnPlateau + global gradient clipping, four contexts accumulated
per step, the supplement's auto-stop, wall-clock and step limits, a JSONL log,
periodic atomic checkpoints and resume.
"""
from __future__ import annotations

import json
import math
import platform
import random
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..training import checkpoint
from . import weights
from ..atomic import write_text
from .apply import Factors, HTPOperator, TreeIndex, htp_apply
from .features import build_input
from ..training.loss import cosine_loss, n_probes, sai_loss, smoothed_probes
from .model import HTPConfig, HTPNet
from ..ordering import rcm_permutation
from ..training.pcg import pcg
from ..scenes.dataset import load_dataset


@dataclass
class TrainSettings:
    """Everything about a run except the network configuration."""

    scales: tuple = (1024,)
    distribution: str = "full"
    frames: int = 100
    loss: str = "cosine"
    lr: float = 2e-4
    warmup: int = 0
    weight_decay: float = 1e-4
    accum: int = 4
    max_steps: int = 100_000
    max_minutes: float | None = None
    log_every: int = 25
    eval_every: int = 200
    ckpt_every: int = 200
    geometry_free: float = 0.25
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None
    compile: bool = False
    out: str = "runs/htp"
    resume: bool = False
    init: str | None = None
    eval_n: int = 1024
    cache_dir: str | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class Context:
    """One precomputed training operator: network input, padded A, partition."""

    inp: object
    A: torch.Tensor
    part: object
    tree: TreeIndex
    a_norm: float


def make_context(A, part, coords=None, density=None, device="cpu") -> Context:
    """Precompute everything the loss needs for one (already ordered) operator."""
    inp = build_input(A, part, coords, density).to(device)
    coo = A.tocoo()
    At = torch.sparse_coo_tensor(np.stack([coo.row, coo.col]), coo.data, size=(part.n_pad,) * 2,
                                 dtype=torch.float32, device=device,
                                 check_invariants=False).coalesce()
    a_norm = float(abs(A).sum(axis=1).max())
    return Context(inp, At, part, TreeIndex(part, device), a_norm)


def frame_contexts(frames, cfg: HTPConfig, geometry_free: float, rng: random.Random, device) -> list:
    """Contexts for scene frames; a fraction drops geometry and uses RCM order (the bare-matrix path)."""
    out = []
    for fr in frames:
        part = cfg.partition(fr.n)
        if rng.random() < geometry_free:
            p = rcm_permutation(fr.A)
            out.append(make_context(fr.A[p][:, p], part, device=device))
        else:
            out.append(make_context(fr.A, part, fr.coords, fr.rho, device))
    return out


def context_loss(net, ctx: Context, kind: str, generator=None) -> torch.Tensor:
    """Loss of the network on one context with fresh smoothed probes."""
    packed = net(ctx.inp, ctx.part)
    f = Factors.unpack(packed, ctx.part)
    apply_m = lambda X: htp_apply(f, ctx.tree, X)  # noqa: E731
    Z = smoothed_probes(ctx.A, ctx.inp.inv_diag, ctx.inp.mask, n_probes(ctx.part.n), generator=generator)
    if kind == "sai":
        return sai_loss(Z, ctx.A, apply_m, ctx.a_norm)
    return cosine_loss(Z, (ctx.A @ Z).detach(), apply_m)


@torch.no_grad()
def evaluate(net, frame, ctx: Context, rtol=1e-8, maxiter=5000) -> dict:
    """Held-out SAI loss and PCG iterations of the current network on one frame."""
    net.eval()
    packed = net(ctx.inp, ctx.part)
    op = HTPOperator(packed.float(), ctx.part)
    g = torch.Generator(device=ctx.A.device).manual_seed(1234)
    f = Factors.unpack(packed, ctx.part)
    sai = float(sai_loss(smoothed_probes(ctx.A, ctx.inp.inv_diag, ctx.inp.mask, 64, generator=g),
                         ctx.A, lambda X: htp_apply(f, ctx.tree, X), ctx.a_norm))
    res = pcg(frame.A, frame.b, op.apply, rtol=rtol, maxiter=maxiter)
    net.train()
    return {"sai_heldout": sai, "pcg_iters": res.iterations, "pcg_reason": res.reason}


class AutoStop:
    """Stop once lr hit its floor and the loss failed to improve by ``rel`` for ``patience`` logs."""

    def __init__(self, min_lr: float, rel: float = 5e-3, patience: int = 10):
        self.min_lr, self.rel, self.patience = min_lr, rel, patience
        self.best, self.bad = math.inf, 0

    def update(self, loss: float, lr: float) -> bool:
        """Record one logged loss; True means stop."""
        if loss < self.best * (1 - self.rel):
            self.best, self.bad = loss, 0
        else:
            self.bad += 1
        return lr <= self.min_lr * (1 + 1e-9) and self.bad >= self.patience


def train(cfg: HTPConfig, s: TrainSettings) -> Path:
    """Run training; returns the path of the final checkpoint (``<out>/final.pt``)."""
    if s.loss not in ("cosine", "sai"):
        raise ValueError(f"unknown loss {s.loss!r}; use cosine or sai")
    if s.threads:
        torch.set_num_threads(s.threads)
    torch.manual_seed(s.seed)
    rng = random.Random(s.seed)
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    dev = torch.device(s.device)
    contexts = []
    for n in s.scales:
        frames = load_dataset(n, "train", s.distribution, count=s.frames, cache_dir=s.cache_dir)
        contexts += frame_contexts(frames, cfg, s.geometry_free, rng, dev)
    held = load_dataset(s.eval_n, "test", s.distribution, count=1, cache_dir=s.cache_dir)[0]
    held_ctx = make_context(held.A, cfg.partition(held.n), held.coords, held.rho, dev)

    net = HTPNet(cfg).to(dev)
    model = torch.compile(net) if s.compile else net
    opt = torch.optim.AdamW(net.parameters(), lr=s.lr, weight_decay=s.weight_decay)
    min_lr = max(s.lr * 1e-3, 1e-6)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=5, threshold=5e-3,
                                                       threshold_mode="rel", min_lr=min_lr)
    stop = AutoStop(min_lr)
    step, elapsed = 0, 0.0
    parent = None
    if s.init:
        p = weights.warm_start(net, s.init)
        parent = {"path": str(s.init), "steps": p.get("steps"), "wall_s": p.get("wall_s"),
                  "scales": p.get("scales"), "device": p.get("device"), "init": p.get("init")}
    last = untrained = evaluate(net, held, held_ctx)
    last_path = out / "last.pt"
    if s.resume and last_path.exists():
        obj = checkpoint.read(last_path)
        net.load_state_dict(obj["state_dict"])
        ex = obj["extra"]
        opt.load_state_dict(ex["opt"])
        sched.load_state_dict(ex["sched"])
        step, elapsed = ex["step"], ex["elapsed"]
        stop.best, stop.bad = ex["stop"]
        untrained = obj["provenance"]["heldout_untrained"]
    log = open(out / "train_log.jsonl", "a")

    def provenance():
        return {"distribution": s.distribution, "scales": list(s.scales), "frames": s.frames, "seed": s.seed,
                "loss": s.loss, "steps": step, "wall_s": round(elapsed, 1), "device": str(dev),
                "machine": platform.node(), "torch": str(torch.__version__),
                "heldout_n": s.eval_n, "heldout": last, "heldout_untrained": untrained, "settings": asdict(s),
                "init": parent}

    def save(path):
        extra = {"opt": opt.state_dict(), "sched": sched.state_dict(), "step": step, "elapsed": elapsed,
                 "stop": [stop.best, stop.bad]}
        checkpoint.save(path, net, provenance(), extra)

    budget = s.max_minutes * 60 if s.max_minutes else math.inf
    from tqdm import tqdm          # the [bench] extra

    bar = tqdm(total=s.max_steps, initial=step, desc="train", dynamic_ncols=True)
    window = []
    t0 = time.perf_counter() - elapsed
    net.train()
    while step < s.max_steps and elapsed < budget:
        if step < s.warmup:
            for group in opt.param_groups:
                group["lr"] = s.lr * (step + 1) / s.warmup
        opt.zero_grad(set_to_none=True)
        total = 0.0
        for ctx in rng.sample(contexts, min(s.accum, len(contexts))):
            loss = context_loss(model, ctx, s.loss) / s.accum
            loss.backward()
            total += loss.item()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        step += 1
        elapsed = time.perf_counter() - t0
        window.append(total)
        bar.update(1)
        if step % s.log_every == 0:
            mean = float(np.mean(window))
            window = []
            sched.step(mean)
            lr = opt.param_groups[0]["lr"]
            row = {"step": step, "loss": mean, "lr": lr, "wall_s": round(elapsed, 2)}
            if step % s.eval_every == 0:
                last = evaluate(net, held, held_ctx)
                row.update(last, heldout_n=s.eval_n)
            log.write(json.dumps(row) + "\n")
            log.flush()
            bar.set_postfix(loss=f"{mean:.4f}", lr=f"{lr:.1e}", it=last.get("pcg_iters", "-"))
            if stop.update(mean, lr):
                break
        if step % s.ckpt_every == 0:
            save(last_path)
    bar.close()
    last = evaluate(net, held, held_ctx)
    log.write(json.dumps({"step": step, "final": True, "wall_s": round(elapsed, 2), **last,
                          "heldout_n": s.eval_n}) + "\n")
    log.close()
    save(last_path)
    return checkpoint.save(out / "final.pt", net, provenance())


def join_logs(stages, out) -> Path:
    """One log from the logs of successive training stages (each fine-tuning the last).

    Parameters
    ----------
    stages : list of (path, heldout_n)
        Stage logs, oldest first, and the N of each stage's held-out frame (for rows
        that do not record it).
    out : path
        Written atomically; steps and wall-clock continue across stages, every row
        gets its ``stage`` (1-based) and evaluation rows their ``heldout_n``.
    """
    rows, step0, wall0 = [], 0, 0.0
    for k, (path, heldout_n) in enumerate(stages, 1):
        stage = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
        if not stage:
            raise ValueError(f"training log {path} is empty")
        for r in stage:
            r.update(step=r["step"] + step0, wall_s=round(r["wall_s"] + wall0, 2), stage=k)
            if "pcg_iters" in r:
                r.setdefault("heldout_n", int(heldout_n))
        step0, wall0 = stage[-1]["step"], stage[-1]["wall_s"]
        rows += stage
    return write_text(out, "".join(json.dumps(r) + "\n" for r in rows))
