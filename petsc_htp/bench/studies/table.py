"""Paper Table 4: setup and solve time and iterations of every method on held-out frames per N."""
from __future__ import annotations

import math

from ..aggregate import cells
from ..baselines import best_table
from ..cases import table_problems
from ..markdown import image, its, md_table, missing, ms, n_label, pm, sci, time_cell, tol
from ..plotting import time_bars
from .base import DIM, FRAMES, SCALES, Study, solve_all

CHART = "table4.png"


def run(methods, scales, frames, extra, tick, dim=2) -> list:
    """Every method on ``frames`` held-out frames per N (one warm-up per method and N)."""
    return solve_all(methods, table_problems(scales, frames, dim), extra, tick, "table")


def _fastest(by, methods, n):
    best = [(c["total_ms"]["mean"], m) for m in methods if (c := by.get((m, n))) and not c["failed"]
            and c["total_ms"]["count"]]
    return min(best)[1] if best else None


def body(res, prefix="") -> str:
    """The Table-4 tables (time and iterations per method and N, setup/solve split) and chart."""
    by, methods, scales = cells(res.rows["table"], "method", "n"), res.methods("table"), res.scales("table")
    frames = res.meta.get("frames", "?")
    head = ["Method"] + [n_label(n) for n in scales]
    main = [[m] + [time_cell(by.get((m, n)), m == _fastest(by, methods, n)) for n in scales] for m in methods]
    split = [[m] + [f"{ms(c['setup_ms']['median'])} + {ms(c['solve_ms']['median'])}"
                    if (c := by.get((m, n))) else "—" for n in scales] for m in methods]
    return "\n\n".join([
        f"Per-frame time to rtol {tol(res.meta.get('rtol', 1e-8))}: mean of setup + solve in ms over {frames} "
        "held-out frames per N, mean PCG iterations in parentheses; **bold**: fastest method without "
        "failures at that N; ✗k/F: frames that failed (reason).",
        md_table(head, main),
        "Setup + solve split (median ms: setup + solve):",
        md_table(head, split),
        image(CHART, "Time per frame", prefix),
    ])


class Table(Study):
    """Paper Table 4 (its rows also feed ``scaling``)."""

    name = "table"
    help = "paper Table 4: setup/solve ms and iterations per method and N"
    default = True
    sizes = (SCALES, FRAMES, DIM)

    def meta(self, settings):
        return {"scales": settings["scales"], "frames": settings["frames"], "dim": settings["dim"]}

    def expected_solves(self, ctx):
        return len(ctx.methods) * len(ctx.settings["scales"]) * ctx.settings["frames"]

    def measure(self, ctx, tick):
        s = ctx.settings
        return run(ctx.methods, s["scales"], s["frames"], ctx.extra, tick, s["dim"])

    def section(self, res):
        by, methods, scales = cells(res.rows["table"], "method", "n"), res.methods("table"), res.scales("table")
        head = ["Method"] + [n_label(n) for n in scales]
        total = [[m] + [f"{ms(c['total_ms']['median'])}; {pm(c['total_ms'], ms)}" if (c := by.get((m, n)))
                        else "—" for n in scales] for m in methods]
        iters = [[m] + [pm(c["iterations"], its) if (c := by.get((m, n))) else "—" for n in scales]
                 for m in methods]
        worst = [[m, sci(max((v for n in scales if (m, n) in by and not missing(v := by[(m, n)]["relres_max"])),
                             default=math.nan))] for m in methods]
        held = [m for m in methods if any(not missing(c["bytes_per_unknown"]["median"])
                                          for n in scales if (c := by.get((m, n))))]
        memory = [[m] + [f"{c['bytes_per_unknown']['median']:.0f}" if (c := by.get((m, n))) and
                         not missing(c["bytes_per_unknown"]["median"]) else "—" for n in scales] for m in held]
        peak = {(r["method"], r["n"]): r["peak_rss_mb"] for r in res.rows["table"] if r.get("peak_rss_mb")}
        rss = [[m] + [f"{peak[(m, n)]:.0f} ({peak[(m, n)] * 2 ** 20 / n:.0f} B/unknown)" if (m, n) in peak else "—"
                      for n in scales] for m in methods]
        return "\n\n".join([
            "## 1. Time per frame (paper Table 4)",
            body(res),
            "Total ms per frame, median; mean ± std:",
            md_table(head, total),
            "Each baseline family at its default and its best swept setting (median ms, iterations):",
            best_table(res.rows["table"], methods, ("n",)),
            "PCG iterations, mean ± std (supplement Table 7):",
            md_table(head, iters),
            "Largest true relative residual among converged frames:",
            md_table(["Method", "max ||b - A x|| / ||b|| (null-space part removed)"], worst),
            "Memory held by the HTP preconditioners (bytes per unknown, median; factors, inverses, coarse "
            "space and the operator copy they keep):",
            md_table(head, memory) if held else "(no HTP method in this run)",
            "Peak RSS of the process (MiB, largest over ranks; per unknown in parentheses) when each method "
            "finished its frames at that N. It only grows during a run, so it is one method's own peak when the "
            "run has one method (as in README's memory runs), else an upper bound:",
            md_table(head, rss) if peak else "(not recorded)",
        ])

    def charts(self, res, out):
        return [time_bars(res, out, "table", CHART, "Per-frame time (setup hatched) to rtol 1e-8")]

    def readme(self, res, prefix):
        return "### Time per frame (paper Table 4)\n\n" + body(res, prefix)

    def summary(self, res):
        return body(res)


STUDY = Table()
