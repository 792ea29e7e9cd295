"""Residual against wall-clock time (KSP monitor) per method, and the time to each tolerance."""
from __future__ import annotations

import math

import numpy as np

from ..aggregate import TOLERANCES, first_failure, group, time_to
from ..cases import Problem, held_out_frames
from ..markdown import image, its, md_table, ms, n_label, tol
from ..plotting import colors, figure, fps_lines, n_axis, save
from .base import DIM, SCALES, Study, solve_all

SUMMARY_CHART = "curves_summary.png"


def chart_name(n) -> str:
    """File name of the residual-against-time chart of one N."""
    return f"curves_n{n}.png"


def run(methods, scales, extra, tick, dim=2) -> list:
    """Every method on the representative frame (the first held-out test frame) of every N, monitored."""
    problems = [Problem(held_out_frames(n, 1, dim=dim)[0], case="curve") for n in scales]
    return solve_all(methods, problems, extra, tick, "curves", monitor=True)


def curve_chart(res, out, n) -> str:
    """Residual against wall-clock time of every method on the representative frame of one N."""
    rows = [r for r in res.rows["curves"] if r["n"] == n]
    color = colors(res.methods("curves"))
    fig, ax = figure(6.5, 4.2)
    ax = ax[0, 0]
    for r in rows:
        pts = np.array(r.get("curve") or [[math.nan, 0, math.nan]], dtype=float)
        ax.plot(pts[:, 0], pts[:, 2], color=color[r["method"]], label=r["method"], lw=1.2)
    for t in TOLERANCES:
        ax.axhline(t, color="grey", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall-clock ms (setup included)")
    ax.set_ylabel("||r_k|| / ||b||")
    ax.set_title(f"Residual against time, N={n}")
    ax.legend(fontsize=7)
    return save(fig, out, chart_name(n))


def summary_chart(res, out) -> str:
    """Time to 1e-3, 1e-6 and 1e-8 against N, one panel per tolerance."""
    methods, scales = res.methods("curves"), res.scales("curves")
    color = colors(methods)
    by = {(r["method"], r["n"]): r for r in res.rows["curves"]}
    fig, axes = figure(12, 3.8, 1, len(TOLERANCES))
    for ax, t in zip(axes[0], TOLERANCES):
        for m in methods:
            reached = [time_to(by.get((m, n), {}).get("curve"), t) for n in scales]
            ax.plot(scales, [math.nan if v is None else v for v in reached], "o-", color=color[m], label=m)
        n_axis(ax, scales)
        ax.set_yscale("log")
        fps_lines(ax)
        ax.set_ylabel("ms")
        ax.set_title(f"time to ||r||/||b|| ≤ {t:g}")
    axes[0, 0].legend(fontsize=7)
    return save(fig, out, SUMMARY_CHART)


class Curves(Study):
    """Speed against accuracy on one frame per N."""

    name = "curves"
    help = "residual against wall-clock per method (KSP monitor), time to 1e-3/1e-6/1e-8"
    default = True
    sizes = (SCALES, DIM)
    readme_links = ((SUMMARY_CHART, "speed against accuracy"),)

    def expected_solves(self, ctx):
        return len(ctx.methods) * len(ctx.settings["scales"])

    def measure(self, ctx, tick):
        return run(ctx.methods, ctx.settings["scales"], ctx.extra, tick, ctx.settings["dim"])

    def section(self, res):
        parts = ["## 2. Speed against accuracy",
                 "Residual ||r_k|| / ||b|| against wall-clock time (setup included, clock started before "
                 "KSPSetUp; KSP monitor timestamps) on the first held-out frame of every N. Time in ms to "
                 "reach each tolerance (— never reached):"]
        groups = group(res.rows["curves"], "n")
        for n in res.scales("curves"):
            by_method = {r["method"]: r for r in groups[(n,)]}
            rows = [[m] + [ms(time_to(r.get("curve"), t)) for t in TOLERANCES]
                    + [its(r.get("iterations")) if r.get("ok") else f"✗ {first_failure([r])}"]
                    for m in res.methods("curves") if (r := by_method.get(m))]
            parts += [f"N = {n_label(n)} (seed {groups[(n,)][0].get('seed')}):",
                      md_table(["Method"] + [tol(t) for t in TOLERANCES] + ["iterations"], rows),
                      image(chart_name(n), f"Residual against time, N={n}")]
        parts.append(image(SUMMARY_CHART, "Time to tolerance against N"))
        return "\n\n".join(parts)

    def charts(self, res, out):
        return [curve_chart(res, out, n) for n in res.scales("curves")] + [summary_chart(res, out)]


STUDY = Curves()
