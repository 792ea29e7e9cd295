"""``petsc-htp bench`` / ``python -m petsc_htp.bench``: flags, the run, the report, README."""
from __future__ import annotations

import argparse
import datetime
import sys
import textwrap
import time
from pathlib import Path

from . import store
from .methods import DEFAULT_METHODS, resolve_methods
from .studies import STUDIES, defaults, sizes

DESCRIPTION = ("Measure every method through PETSc on the same frames and write a results folder: raw JSONL, "
               "meta.json, report.md and PNG charts (the source of every performance number in README).")


def epilog() -> str:
    """The studies, one line each, for ``-h``."""
    lines = [f"studies (--studies, default {' '.join(defaults())}; --study NAME adds one; --all runs every one):"]
    lines += [textwrap.fill(s.help, 103, initial_indent=f"  {name:<16}", subsequent_indent=" " * 18)
              for name, s in STUDIES.items()]
    return "\n".join(lines) + "\n"


def build_parser() -> argparse.ArgumentParser:
    """Flags of ``petsc-htp bench``; unset sizes take the full or (--quick) CI defaults."""
    p = argparse.ArgumentParser(prog="petsc-htp bench", description=DESCRIPTION, epilog=epilog(),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", help="results folder (default results/bench-<date>-<time>)")
    p.add_argument("--quick", action="store_true", help="CI-sized run: small N, few frames, tiny budgets")
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS),
                   help="options-file stems in options/, paths to .opts files, or 'pyamg' (default: %(default)s)")
    p.add_argument("--studies", nargs="+", choices=list(STUDIES), default=defaults(), metavar="STUDY",
                   help="studies to run (default: %(default)s; see below)")
    p.add_argument("--study", action="append", choices=list(STUDIES), default=[], metavar="STUDY",
                   help="add one study (repeatable)")
    p.add_argument("--all", action="store_true", help="run every study")
    p.add_argument("--fastpath", action="store_true", help="add the fast-path study")
    p.add_argument("--checkpoint", help="HTP checkpoint (sets -htp_checkpoint; default the shipped model)")
    p.add_argument("--device", help="HTP device for -htp_device and the fast path: cpu, cuda or auto")
    p.add_argument("--threads", type=int, default=0, help="torch threads (and -htp_threads); 0 keeps the default")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    group = p.add_argument_group("sizes (defaults: full run / --quick)")
    for size in sizes():
        size.add_to(group)
    a = p.add_argument_group("other actions")
    a.add_argument("--report-only", metavar="DIR", help="rebuild report.md and the charts of DIR from its JSONL")
    a.add_argument("--readme", nargs="?", const="", metavar="RESULTS_DIR",
                   help="rewrite README's results block from RESULTS_DIR (default the newest results/bench-*)")
    a.add_argument("--readme-file", default="README.md", help="README to rewrite (%(default)s, in the working directory)")
    return p


def _settings(args) -> dict:
    """Every size: its flag when given, else the full or quick default."""
    out = {}
    for s in sizes():
        given = getattr(args, s.name, None)
        out[s.name] = (s.quick if args.quick else s.full) if given is None else given
    return out


def _selected(args) -> list:
    """Studies to run, in registry order."""
    wanted = set(STUDIES if args.all else args.studies + args.study + (["fastpath"] if args.fastpath else []))
    return [s for s in STUDIES if s in wanted]


def _lead() -> bool:
    """Whether this process writes and prints: rank 0 of an MPI run (``mpiexec -n 2 petsc-htp bench``)."""
    from petsc4py import PETSc

    return PETSc.COMM_WORLD.getRank() == 0


def _measure(study, ctx, args) -> list:
    """Run one study's measurement under a progress bar (rank 0's); return its rows."""
    from tqdm import tqdm

    with tqdm(total=study.expected_solves(ctx), desc=study.name, unit="solve", dynamic_ncols=True,
              disable=args.no_progress or not _lead()) as bar:
        return study.measure(ctx, lambda: bar.update(1))


def run(args, argv) -> Path:
    """Measure the selected studies into the results folder; write meta.json and the rows (rank 0).

    Under MPI every rank runs every study: PETSc methods solve each frame on all ranks, the serial pyamg and
    AMGCL on rank 0 alone.
    """
    import torch

    from .meta import collect
    from .studies.base import Context

    if args.threads:
        torch.set_num_threads(args.threads)
    out = Path(args.out or Path("results") / f"bench-{datetime.datetime.now():%Y%m%d-%H%M%S}")
    ctx = Context(_settings(args), resolve_methods(args.methods), out, args.checkpoint, args.device, args.threads)
    selected = _selected(args)
    meta = collect(ctx, argv, args.quick, selected)
    lead = _lead()
    if lead:
        store.write_json(out / store.META, meta)
    measured = set()
    for name in selected:
        source = STUDIES[STUDIES[name].data]
        t0 = time.perf_counter()
        if source.name not in measured:
            rows = _measure(source, ctx, args)
            if lead:
                store.write_jsonl(store.study_path(out, source.name), rows)
            measured.add(source.name)
        meta["study_s"][name] = round(time.perf_counter() - t0, 1)
        if lead:
            store.write_json(out / store.META, meta)
    return out


def finish(out) -> str:
    """Draw the charts and write report.md of a results folder; return the studies' summaries (Table 4)."""
    from .report import build, load, present

    res = load(out)
    for study in present(res):
        study.charts(res, out)
    store.write_text(Path(out) / store.REPORT, build(res))
    return "\n\n".join(text for s in present(res) if (text := s.summary(res)))


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
        if not _lead():
            return 0
        table = finish(out)
    except ValueError as exc:
        print(f"petsc-htp bench: error: {exc}", file=sys.stderr)
        return 2
    print(f"results: {out}\nreport: {out / store.REPORT}\n\n{table}")
    return 0
