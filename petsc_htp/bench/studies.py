"""Measurements of every study: each returns the result rows its report section reads.

``table``/``scaling`` share one measurement (held-out frames per N); the
trained-model studies (``generalization``, ``size``, ``profile``) train their
own small models within a :class:`~petsc_htp.bench.training.Budget`.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from .. import checkpoint
from ..pcg import jacobi, pcg
from . import cases, training
from .methods import resolve_method
from .runner import htp_options, run_method
from .store import read_jsonl

SHIPPED_LOG = checkpoint.DEFAULT.parent / "train_log.jsonl"


def _tag(rows, **fields):
    for row in rows:
        row.update(fields)
    return rows


def _solve_all(methods, problems, extra, tick, study, **kw):
    """Every method on every problem (methods outermost), rows tagged with ``study``."""
    return [row for m in methods for row in _tag(run_method(m, problems, extra, tick=tick, **kw), study=study)]


# ------------------------------------------------------------------ cheap studies

def table_rows(methods, scales, frames, extra, tick):
    """Paper Table 4: every method on ``frames`` held-out frames per N (one warm-up per method and N)."""
    return _solve_all(methods, cases.table_problems(scales, frames), extra, tick, "table")


def curve_rows(methods, scales, extra, tick):
    """Residual against wall-clock (KSP monitor) on the representative frame of every N."""
    return _solve_all(methods, cases.curve_problems(scales), extra, tick, "curves", monitor=True)


def stability_rows(methods, n, frames, large_n, odd_n, extra, tick):
    """Every method on every stress case (no warm-up: iterations and failures matter here)."""
    problems = cases.stress_problems(n, frames, large_n, odd_n)
    return _solve_all(methods, problems, extra, tick, "stability", warmup=False)


# ------------------------------------------------------------ trained-model studies

def generalization_models(out, cfg, budget) -> dict:
    """One model of configuration ``cfg`` per training distribution of :data:`cases.TRAIN_SETS`."""
    return {name: training.trained_checkpoint(out, cfg, name, "cosine", budget) for name, _ in cases.TRAIN_SETS}


def generalization_rows(models, n, frames, extra, tick):
    """Paper Table 6 and the supplement grid: every model (``{train set: checkpoint}``) on every eval set.

    CG + Jacobi on the same frames is the baseline of the speedups.
    """
    jac, htp = resolve_method("cg_jacobi"), resolve_method("cg_htp")
    rows = []
    for name, _ in cases.EVAL_SETS:
        problems = cases.eval_problems(name, n, frames)
        rows += _tag(run_method(jac, problems, extra, tick=tick), study="generalization", eval=name, train=None)
        for train_set, path in models.items():
            got = run_method(htp, problems, extra + htp_options(checkpoint=path), tick=tick)
            rows += _tag(got, study="generalization", eval=name, train=train_set, **training.model_info(path))
    return rows


def size_configs(base):
    """(configuration, loss) pairs: the base, then one change at a time (d, n_l, highways, loss)."""
    out = [(base, "cosine")]
    out += [(dataclasses.replace(base, d=d), "cosine") for d in (32, 64, 128)]
    out += [(dataclasses.replace(base, n_layers=k), "cosine") for k in (1, 2, 3)]
    out += [(dataclasses.replace(base, highways=not base.highways), "cosine"), (base, "sai")]
    keys = {}
    for cfg, loss in out:
        keys.setdefault(training.model_key(cfg, "full", loss), (cfg.validate(), loss))
    return list(keys.values())


def size_models(out, base, budget) -> list:
    """``(configuration, loss, checkpoint)`` of every :func:`size_configs` model, trained on the full distribution."""
    return [(cfg, loss, training.trained_checkpoint(out, cfg, "full", loss, budget)) for cfg, loss in size_configs(base)]


def size_rows(models, base, scales, frames, extra, tick):
    """Model size study: CG + HTP with every ``(configuration, loss, checkpoint)`` on held-out frames."""
    htp = resolve_method("cg_htp")
    problems = cases.table_problems(scales, frames)
    rows = []
    for cfg, loss, path in models:
        got = run_method(htp, problems, extra + htp_options(checkpoint=path), tick=tick)
        rows += _tag(got, study="size", config=training.label(cfg, loss), base=cfg == base and loss == "cosine",
                     **training.model_info(path))
    return rows


def _log_provenance(log_path, ckpt):
    """Provenance of the model a training log belongs to (checkpoint beside it, else ``ckpt``)."""
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
    sizes = sorted({r.get("heldout_n") or prov.get("heldout_n") for r in train if r.get("pcg_iters") is not None} - {None})
    rows = []
    for n in sizes:
        frame = cases.held_out_frames(n, 1, prov.get("distribution", "full"))[0]
        rows += [{"kind": "baseline", "method": name, "n": frame.n,
                  "iterations": pcg(frame.A, frame.b, m, rtol=1e-8, maxiter=20000).iterations}
                 for name, m in (("none", None), ("jacobi", jacobi(frame.A)))]
    return rows


def profile_sources(out, cfg, budget, log_path=None, ckpt=None):
    """(training log, checkpoint) of the profile: given, else the shipped model's, else a model trained now."""
    log_path = Path(log_path) if log_path else (SHIPPED_LOG if SHIPPED_LOG.is_file() else None)
    ckpt = ckpt or (checkpoint.DEFAULT if checkpoint.DEFAULT.is_file() else None)
    if log_path is None or ckpt is None:
        trained = training.trained_checkpoint(out, cfg, "full", "cosine", budget)
        log_path = log_path or trained.parent / "train_log.jsonl"
        ckpt = ckpt or trained
    return log_path, ckpt


def profile_rows(log_path, ckpt, spectrum_n):
    """Training profile (log rows + baselines) and the spectra of M A on one frame of ``spectrum_n``."""
    from ..inference import HTP
    from .spectrum import spectrum_rows

    rows = [{"kind": "source", "train_log": str(log_path), "checkpoint": str(ckpt)}]
    train = read_jsonl(log_path)
    rows += [{"kind": "train", **r} for r in train]
    rows += _baseline_rows(train, _log_provenance(log_path, ckpt))
    frame = cases.held_out_frames(spectrum_n, 1)[0]
    rows += [{"kind": "spectrum", **r} for r in spectrum_rows(frame, HTP.load(ckpt, device="cpu"))]
    return _tag(rows, study="profile")


# -------------------------------------------------------------------- fast path

def fastpath_rows(scales, frames, ckpt, device):
    """GPU CUDA-Graph PCG (eager on CPU) on the table's frames; the first frame per N is a discarded warm-up."""
    from ..fastpath import METHODS, run_fastpath
    from ..inference import HTP, resolve_device

    dev = resolve_device(device)
    methods, htp, note = list(METHODS), None, None
    try:
        htp = HTP.load(ckpt, device=str(dev))
    except Exception as exc:  # no usable checkpoint: the classical methods still run
        methods.remove("htp")
        note = f"htp skipped: {type(exc).__name__}: {exc}"
    rows = []
    for n in scales:
        held = cases.held_out_frames(n, frames)
        got = run_fastpath([held[0]] + held, methods, htp, dev)
        rows += got[len(methods):]
    for row in rows:
        row.update(study="fastpath", ok=row.get("reason") == "converged", note=note,
                   failure=None if row.get("reason") == "converged" else row.get("reason"))
    return rows
