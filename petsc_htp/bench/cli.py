"""``petsc-htp bench`` / ``python -m petsc_htp.bench``: flags, the run, the report, README."""
from __future__ import annotations

import argparse
import datetime
import hashlib
import os
import platform
import sys
import time
from pathlib import Path

from . import store
from ..options import ROOT
from .methods import DEFAULT_METHODS, resolve_methods

FULL = dict(scales=[1024, 2048, 4096, 8192, 16384], frames=20, stress_n=4096, stress_frames=3, large_n=65536,
            odd_n=3000, gen_n=4096, gen_frames=20, train_minutes=15.0, train_steps=100_000,
            train_scales=[1024, 2048], train_frames=100, eval_n=1024, log_every=25, eval_every=200,
            size_scales=[2048, 4096, 8192], size_frames=5, spectrum_n=1024)
QUICK = dict(scales=[256, 512], frames=2, stress_n=256, stress_frames=1, large_n=2048, odd_n=300, gen_n=256,
             gen_frames=2, train_minutes=0.5, train_steps=2, train_scales=[256], train_frames=2, eval_n=256,
             log_every=1, eval_every=2, size_scales=[256], size_frames=1, spectrum_n=256)

DESCRIPTION = ("Measure every method through PETSc on the same frames and write a results folder: raw JSONL, "
               "meta.json, report.md and PNG charts (the source of every performance number in README).")
EPILOG = """studies (--studies, default the first four; --study NAME adds one; --all runs every one):
  table           paper Table 4: setup/solve ms and iterations per method and N
  curves          residual against wall-clock per method (KSP monitor), time to 1e-3/1e-6/1e-8
  scaling         time against N (log-log), fitted exponents, 60/24 fps budgets (uses table's data)
  stability       methods x stress cases (contrast, closed barriers, large/odd N, tight rtol, natural
                  ordering, buoyancy and inconsistent rhs)
  generalization  paper Table 6 + grid: trains 4 models (--train-budget-minutes each)
  size            model size sweep (d, n_l, highways, loss) with a Pareto chart: trains ~7 models
  profile         training profile from --train-log, and the spectrum of M A
  fastpath        torch CUDA-Graph PCG (eager on CPU), also --fastpath
"""


def build_parser() -> argparse.ArgumentParser:
    """Flags of ``petsc-htp bench``; unset sizes take the full or (--quick) CI defaults."""
    p = argparse.ArgumentParser(prog="petsc-htp bench", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", help="results folder (default results/bench-<date>-<time>)")
    p.add_argument("--quick", action="store_true", help="CI-sized run: small N, few frames, tiny budgets")
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS),
                   help="options-file stems in options/, paths to .opts files, or 'pyamg' (default: %(default)s)")
    p.add_argument("--studies", nargs="+", choices=store.STUDIES, default=list(store.CHEAP), metavar="STUDY",
                   help="studies to run (default: %(default)s; see below)")
    p.add_argument("--study", action="append", choices=store.STUDIES, default=[], metavar="STUDY",
                   help="add one study (repeatable)")
    p.add_argument("--all", action="store_true", help="run every study")
    p.add_argument("--fastpath", action="store_true", help="add the fast-path study")
    p.add_argument("--checkpoint", help="HTP checkpoint (sets -htp_checkpoint; default the shipped model)")
    p.add_argument("--device", help="HTP device for -htp_device and the fast path: cpu, cuda or auto")
    p.add_argument("--threads", type=int, default=0, help="torch threads (and -htp_threads); 0 keeps the default")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    g = p.add_argument_group("sizes (defaults: full run / --quick)")
    g.add_argument("--scales", type=int, nargs="+", help=f"N of table/curves/fastpath ({FULL['scales']} / {QUICK['scales']})")
    g.add_argument("--frames", type=int, help="held-out frames per N (20 / 2)")
    g.add_argument("--stress-n", type=int, help="N of the stress cases (4096 / 256)")
    g.add_argument("--stress-frames", type=int, help="frames per stress case (3 / 1)")
    g.add_argument("--large-n", type=int, help="the 'large N' stress case (65536 / 2048)")
    g.add_argument("--odd-n", type=int, help="the 'odd N' stress case (3000 / 300)")
    g.add_argument("--gen-n", type=int, help="N of the generalization study (4096 / 256)")
    g.add_argument("--gen-frames", type=int, help="frames per generalization eval set (20 / 2)")
    g.add_argument("--train-budget-minutes", dest="train_minutes", type=float,
                   help="wall-clock limit per study model (15 / 0.5)")
    g.add_argument("--train-steps", type=int, help="step limit per study model (100000 / 2)")
    g.add_argument("--train-scales", type=int, nargs="+", help="training N of study models (1024 2048 / 256)")
    g.add_argument("--train-frames", type=int, help="training frames per scale (100 / 2)")
    g.add_argument("--size-scales", type=int, nargs="+", help="N of the size study (2048 4096 8192 / 256)")
    g.add_argument("--size-frames", type=int, help="frames per N in the size study (5 / 1)")
    g.add_argument("--train-log", help="training log of the profile study (default the shipped model's)")
    g.add_argument("--spectrum-n", type=int, help="N of the spectrum (1024 / 256)")
    a = p.add_argument_group("other actions")
    a.add_argument("--report-only", metavar="DIR", help="rebuild report.md and the charts of DIR from its JSONL")
    a.add_argument("--readme", nargs="?", const="", metavar="RESULTS_DIR",
                   help="rewrite README's results block from RESULTS_DIR (default the newest results/bench-*)")
    a.add_argument("--readme-file", default=str(ROOT / "README.md"), help="README to rewrite (%(default)s)")
    return p


def _settings(args) -> dict:
    """The size settings: explicit flags, else the full or quick defaults."""
    base = QUICK if args.quick else FULL
    return {k: getattr(args, k, None) if getattr(args, k, None) is not None else v for k, v in base.items()}


def _selected(args) -> list:
    """Studies to run, in canonical order."""
    wanted = set(store.STUDIES if args.all else args.studies + args.study + (["fastpath"] if args.fastpath else []))
    return [s for s in store.STUDIES if s in wanted]


# ------------------------------------------------------------------------- meta

def git_commit(root=ROOT):
    """HEAD's commit read from the .git folder (no git process), or None."""
    git = Path(root) / ".git"
    try:
        head = (git / "HEAD").read_text().strip()
        if not head.startswith("ref: "):
            return head
        ref = head[5:]
        if (git / ref).is_file():
            return (git / ref).read_text().strip()
        for line in (git / "packed-refs").read_text().splitlines():
            if line.endswith(" " + ref):
                return line.split()[0]
    except OSError:
        return None
    return None


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (platform.processor() elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _versions() -> dict:
    import numpy
    import petsc4py
    import scipy
    import torch
    from petsc4py import PETSc

    out = {"python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__,
           "torch": torch.__version__, "petsc4py": petsc4py.__version__,
           "PETSc": ".".join(map(str, PETSc.Sys.getVersion()))}
    try:
        import pyamg
        out["pyamg"] = pyamg.__version__
    except ImportError:
        out["pyamg"] = "missing"
    return out


def _checkpoint_meta(path):
    from .. import checkpoint

    path = Path(path).resolve() if path else checkpoint.DEFAULT
    if not path.is_file():
        return {"path": str(path), "sha256": "missing"}
    return {"path": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest()[:12]}


def collect_meta(args, argv, settings, methods, selected, budget) -> dict:
    """Everything about the machine and the run that the report states."""
    import torch

    from ..inference import resolve_device
    from .runner import common_setting

    return {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "cpu": cpu_model(), "cores": os.cpu_count()},
        "commit": git_commit(), "versions": _versions(),
        "threads": {"torch": torch.get_num_threads(), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "unset"),
                    "MPI ranks": 1},
        "checkpoint": _checkpoint_meta(args.checkpoint), "device": str(resolve_device(args.device or "auto")),
        "argv": list(argv), "quick": args.quick, "methods": [m.name for m in methods], "studies": selected,
        "scales": settings["scales"], "frames": settings["frames"],
        "rtol": common_setting("ksp_rtol", 1e-8), "max_it": int(common_setting("ksp_max_it", 10000)),
        "stress": {"n": settings["stress_n"], "frames": settings["stress_frames"],
                   "large_n": settings["large_n"], "odd_n": settings["odd_n"]},
        "generalization": {"n": settings["gen_n"], "frames": settings["gen_frames"]},
        "size": {"scales": settings["size_scales"], "frames": settings["size_frames"]},
        "budget": {"text": budget.describe(), "minutes": budget.minutes, "steps": budget.steps},
        "study_s": {},
    }


# -------------------------------------------------------------------------- run

def _bar(args, desc, total):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="solve", dynamic_ncols=True, disable=args.no_progress)


def _measure(study, args, s, methods, extra, budget, out):
    """Run one study; returns its rows (``scaling`` reuses ``table``'s and measures nothing)."""
    from . import cases, studies, training
    from .cases import EVAL_SETS

    cfg = training.base_config(args.checkpoint)
    m = len(methods)
    totals = {"table": m * len(s["scales"]) * s["frames"], "curves": m * len(s["scales"]),
              "stability": m * len(cases.STRESS) * s["stress_frames"],
              "generalization": len(EVAL_SETS) * (1 + len(cases.TRAIN_SETS)) * s["gen_frames"],
              "size": len(studies.size_configs(cfg)) * len(s["size_scales"]) * s["size_frames"]}
    with _bar(args, study, totals.get(study, 0)) as bar:
        tick = lambda: bar.update(1)  # noqa: E731
        if study == "table":
            return studies.table_rows(methods, s["scales"], s["frames"], extra, tick)
        if study == "curves":
            return studies.curve_rows(methods, s["scales"], extra, tick)
        if study == "stability":
            return studies.stability_rows(methods, s["stress_n"], s["stress_frames"], s["large_n"], s["odd_n"],
                                          extra, tick)
        if study == "generalization":
            models = studies.generalization_models(out, cfg, budget)
            return studies.generalization_rows(models, s["gen_n"], s["gen_frames"], extra, tick)
        if study == "size":
            models = studies.size_models(out, cfg, budget)
            return studies.size_rows(models, cfg, s["size_scales"], s["size_frames"], extra, tick)
        if study == "profile":
            log, ckpt = studies.profile_sources(out, cfg, budget, args.train_log, args.checkpoint)
            return studies.profile_rows(log, ckpt, s["spectrum_n"])
        return studies.fastpath_rows(s["scales"], s["frames"], args.checkpoint, args.device or "auto")


def _budget(args, s):
    from ..inference import resolve_device
    from .training import Budget

    return Budget(minutes=s["train_minutes"], steps=s["train_steps"], scales=tuple(s["train_scales"]),
                  frames=s["train_frames"], eval_n=s["eval_n"], log_every=s["log_every"],
                  eval_every=s["eval_every"], device=str(resolve_device(args.device or "auto")))


def run(args, argv) -> Path:
    """Measure the selected studies into the results folder; write meta, JSONL, charts and report."""
    import torch

    from .runner import htp_options

    if args.threads:
        torch.set_num_threads(args.threads)
    s = _settings(args)
    methods = resolve_methods(args.methods)
    selected = _selected(args)
    out = Path(args.out or ROOT / "results" / f"bench-{datetime.datetime.now():%Y%m%d-%H%M%S}")
    budget = _budget(args, s)
    meta = collect_meta(args, argv, s, methods, selected, budget)
    store.write_json(out / store.META, meta)
    extra = htp_options(args.checkpoint and Path(args.checkpoint).resolve(), args.device, args.threads)
    measured = set()
    for study in selected:
        data = "table" if study == "scaling" else study
        t0 = time.perf_counter()
        if data not in measured:
            store.write_jsonl(store.study_path(out, data), _measure(data, args, s, methods, extra, budget, out))
            measured.add(data)
        meta["study_s"][study] = round(time.perf_counter() - t0, 1)
        store.write_json(out / store.META, meta)
    return out


def finish(out) -> str:
    """Draw the charts and write report.md of a results folder; return the Table-4 text."""
    from . import charts, report

    res = report.load(out)
    charts.draw_all(res, out)
    store.write_text(Path(out) / store.REPORT, report.build(res))
    return report.table4_body(res) if "table" in res.rows else ""


def main(argv=None) -> int:
    """Entry point; returns the exit status (2 on a usage error)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    try:
        if args.readme is not None:
            from .readme import latest_results, rewrite

            path = rewrite(args.readme_file, args.readme or latest_results())
            print(f"rewrote the results block of {path}")
            return 0
        out = Path(args.report_only) if args.report_only else run(args, argv)
        table = finish(out)
    except ValueError as exc:
        print(f"petsc-htp bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"results: {out}\nreport: {out / store.REPORT}\n\n{table}")
    return 0
