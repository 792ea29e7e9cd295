"""Training profile of a model (its log, against Jacobi and no preconditioner) and the spectrum of M A."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..aggregate import group
from ..cases import held_out_frames
from ..markdown import image, md_table, n_label, ratio, sci
from ..plotting import figure, save
from ..store import read_jsonl
from .base import TRAINING, Size, Study, tag

CHART = "profile.png"
VARIANTS = ("cg_twolevel_const", "cg_twolevel_eig", "cg_twolevel_learned")   # spectra beside the paper's HTP
SPECTRUM_CHART = "spectrum.png"


def shipped_log() -> Path:
    """The shipped model's training log."""
    from ...training.checkpoint import DEFAULT

    return DEFAULT.parent / "train_log.jsonl"


def _log_provenance(log_path, ckpt):
    """Provenance of the model a training log belongs to (checkpoint beside it, else ``ckpt``)."""
    from ...training import checkpoint

    folder = Path(log_path).parent
    for cand in (folder / "final.pt", folder / "last.pt", ckpt):
        try:
            return checkpoint.read(cand).get("provenance", {})
        except checkpoint.CheckpointError:
            continue
    return {}


def _baseline_rows(train, prov):
    """Unpreconditioned and Jacobi PCG iterations on every held-out frame of the log (grey lines).

    Evaluation rows name their frame's N (``heldout_n``); older logs fall back to the provenance's.
    """
    from ...training.pcg import jacobi, pcg

    sizes = sorted({r.get("heldout_n") or prov.get("heldout_n") for r in train if r.get("pcg_iters") is not None}
                   - {None})
    rows = []
    for n in sizes:
        frame = held_out_frames(n, 1, prov.get("distribution", "full"))[0]
        rows += [{"kind": "baseline", "method": name, "n": frame.n,
                  "iterations": pcg(frame.A, frame.b, m, rtol=1e-8, maxiter=20000).iterations}
                 for name, m in (("none", None), ("jacobi", jacobi(frame.A)))]
    return rows


def sources(out, cfg, budget, log_path=None, ckpt=None):
    """(training log, checkpoint) of the profile: given, else the shipped model's, else a model trained now."""
    from ...training import checkpoint
    from ..training import trained_checkpoint

    log_path = Path(log_path) if log_path else (shipped_log() if shipped_log().is_file() else None)
    ckpt = ckpt or (checkpoint.DEFAULT if checkpoint.DEFAULT.is_file() else None)
    if log_path is None or ckpt is None:
        trained = trained_checkpoint(out, cfg, "full", "cosine", budget)
        log_path = log_path or trained.parent / "train_log.jsonl"
        ckpt = ckpt or trained
    return log_path, ckpt


def run(log_path, ckpt, spectrum_n) -> list:
    """Training profile (log rows + baselines) and the spectra of M A on one frame of ``spectrum_n``."""
    from ...paper.inference import HTP
    from ..spectrum import spectrum_rows

    rows = [{"kind": "source", "train_log": str(log_path), "checkpoint": str(ckpt)}]
    train = read_jsonl(log_path)
    rows += [{"kind": "train", **r} for r in train]
    rows += _baseline_rows(train, _log_provenance(log_path, ckpt))
    frame = held_out_frames(spectrum_n, 1)[0]
    rows += [{"kind": "spectrum", **r} for r in spectrum_rows(frame, HTP.load(ckpt, device="cpu"), VARIANTS)]
    return [tag(r, study="profile") for r in rows]


def _its_at(row):
    return f"{row['pcg_iters']}" + (f" at N={row['heldout_n']}" if row.get("heldout_n") else "")


def _train_summary(train):
    logged = [r for r in train if "loss" in r]
    evals = [r for r in train if r.get("pcg_iters") is not None]
    last = train[-1] if train else {}
    best = min(evals, key=lambda r: r["pcg_iters"]) if evals else None
    return (f"{last.get('step', 0)} steps in {last.get('wall_s', 0) / 60:.1f} min; loss "
            f"{logged[0]['loss']:.4g} → {logged[-1]['loss']:.4g}; " if logged else "no loss rows; ") + (
        f"held-out PCG iterations {_its_at(evals[0])} → {_its_at(evals[-1])} "
        f"(best {_its_at(best)} at step {best['step']})" if evals else "no held-out evaluations")


def _minutes_to_steps(logged):
    """(forward, inverse) interpolation between wall-clock minutes and steps of a log."""
    t = np.array([0.0] + [r["wall_s"] / 60 for r in logged])
    s = np.array([0.0] + [float(r["step"]) for r in logged])
    return (lambda x: np.interp(x, t, s)), (lambda y: np.interp(y, s, t))


def profile_chart(res, out) -> str:
    """Loss and held-out SAI loss (top), held-out PCG iterations (bottom) against wall-clock minutes."""
    rows = res.rows["profile"]
    train = [r for r in rows if r.get("kind") == "train"]
    logged = [r for r in train if "loss" in r]
    evals = [r for r in train if r.get("pcg_iters") is not None]
    fig, axes = figure(8, 6, rows=2)
    ax, pcg = axes[0, 0], axes[1, 0]
    ax.plot([r["wall_s"] / 60 for r in logged], [r["loss"] for r in logged], color="tab:blue", label="cosine loss")
    ax.set_ylabel("training loss", color="tab:blue")
    sai = ax.twinx()
    sizes = sorted({r.get("heldout_n") for r in evals}, key=lambda n: n or 0)
    named = len(sizes) > 1 or sizes != [None]
    for k, n in enumerate(sizes):
        sel = [r for r in evals if r.get("heldout_n") == n and r.get("sai_heldout")]
        sai.plot([r["wall_s"] / 60 for r in sel], [r["sai_heldout"] for r in sel], "--", color=f"C{k + 1}",
                 label="held-out SAI loss" + (f", N={n}" if named else ""))
    sai.set_ylabel("held-out SAI loss (dashed)")
    handles = [h for a in (ax, sai) for h in a.get_lines() if not h.get_label().startswith("_")]
    ax.legend(handles, [h.get_label() for h in handles], fontsize=7, loc="upper right")
    if logged:
        steps = ax.secondary_xaxis("top", functions=_minutes_to_steps(logged))
        steps.set_xlabel("optimizer steps")
    ax.set_title("Training profile")
    for k, n in enumerate(sizes):
        sel = [r for r in evals if r.get("heldout_n") == n]
        pcg.plot([r["wall_s"] / 60 for r in sel], [r["pcg_iters"] for r in sel], "o-", ms=3, color=f"C{k + 1}",
                 label="held-out PCG iterations" + (f", N={n}" if named else ""))
    for r in (r for r in rows if r.get("kind") == "baseline"):
        pcg.axhline(r["iterations"], color="grey", ls=":", lw=1)
        pcg.annotate(r["method"] + (f", N={r['n']}" if named else ""), (0.01, r["iterations"]),
                     xycoords=("axes fraction", "data"), fontsize=7, color="grey", va="bottom")
    pcg.legend(fontsize=7, loc="upper right")
    pcg.set_yscale("log")
    pcg.set_ylabel("PCG iterations (held-out frame)")
    pcg.set_xlabel("wall-clock minutes")
    pcg.sharex(ax)
    return save(fig, out, CHART)


def spectrum_chart(res, out) -> str:
    """Eigenvalues of M A per preconditioner (jittered strips, log axis) with κ in the labels."""
    spec = [r for r in res.rows["profile"] if r.get("kind") == "spectrum"]
    fig, ax = figure(8, 1.2 + 0.9 * max(len(spec), 1))
    ax = ax[0, 0]
    rng = np.random.default_rng(0)
    for i, r in enumerate(spec):
        e = np.asarray(r["eigs"], dtype=float)
        pos = e[e > 0]
        ax.plot(pos, i + rng.uniform(-0.25, 0.25, pos.size), ".", ms=2, alpha=0.6)
        if (e <= 0).any():
            ax.annotate(f"{int((e <= 0).sum())} eigenvalues ≤ 0 not shown", (1.0, i),
                        xycoords=("axes fraction", "data"), ha="right", fontsize=7, color="tab:red")
    ax.set_yticks(range(len(spec)), [f"{r['method']} (κ={r['kappa']:.2g})" for r in spec])
    ax.set_xscale("log")
    ax.set_xlabel("eigenvalue of M A")
    ax.set_title(f"Spectrum of M A, N={spec[0]['n'] if spec else '?'}")
    return save(fig, out, SPECTRUM_CHART)


class Profile(Study):
    """Training profile and spectrum (trains a model only when no log or checkpoint is at hand)."""

    name = "profile"
    help = "training profile from --train-log, and the spectrum of M A"
    sizes = TRAINING + (Size("train_log", None, None, "training log of the profile study (default the shipped "
                                                      "model's)", kind=str),
                        Size("spectrum_n", 1024, 256, "N of the spectrum"))
    readme_links = ((CHART, "training profile"), (SPECTRUM_CHART, "spectrum"))

    def measure(self, ctx, tick):
        log, ckpt = sources(ctx.out, ctx.config, ctx.budget, ctx.settings["train_log"], ctx.checkpoint)
        return run(log, ckpt, ctx.settings["spectrum_n"])

    def section(self, res):
        kinds = group(res.rows["profile"], "kind")
        source = kinds.get(("source",), [{}])[0]
        base = {f"{r['method']} (N={r['n']})": r["iterations"] for r in kinds.get(("baseline",), [])}
        spec = kinds.get(("spectrum",), [])
        k0 = spec[0]["kappa"] if spec else math.nan
        table = [[r["method"], sci(r["kappa"]), ratio(k0 / r["kappa"]), f"{r['eigs'][0]:.3g}",
                  f"{r['eigs'][-1]:.3g}", "yes" if r["indefinite"] else "no"] for r in spec]
        baseline = ("; baselines on the held-out frames: " + ", ".join(f"{k} {v} its" for k, v in base.items())
                    if base else "")
        return "\n\n".join([
            "## 7. Training profile and spectrum",
            f"Training log `{source.get('train_log', '?')}`: {_train_summary(kinds.get(('train',), []))}"
            f"{baseline}.",
            image(CHART, "Training profile"),
            f"Spectrum of M A on the first held-out frame at N = {n_label(spec[0]['n']) if spec else '?'} "
            "(dense eigendecomposition, null-space eigenvalue removed; "
            f"HTP from `{source.get('checkpoint', '?')}`; the two-level variants through HTPPC with their options "
            "files). "
            "κ = max|λ| / min|λ|; reduction against no preconditioner:",
            md_table(["M", "κ", "reduction", "λ min", "λ max", "indefinite"], table),
            image(SPECTRUM_CHART, "Spectra of M A"),
        ])

    def charts(self, res, out):
        return [profile_chart(res, out), spectrum_chart(res, out)]


STUDY = Profile()
