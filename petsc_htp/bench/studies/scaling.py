"""Time against N: fitted exponents and the frame budgets, from the rows of ``table``."""
from __future__ import annotations

import numpy as np

from ..aggregate import FPS_BUDGETS, cells, largest_within, scaling_exponent, value
from ..markdown import image, md_table, ms, n_label
from ..plotting import colors, figure, fps_lines, n_axis, save
from .base import Study

CHART = "scaling.png"


def chart(res, out) -> str:
    """log-log median total ms against N per method with fps budget lines and fitted exponents."""
    methods, scales = res.methods("table"), res.scales("table")
    by = cells(res.rows["table"], "method", "n")
    color = colors(methods)
    fig, ax = figure(6.5, 4.5)
    ax = ax[0, 0]
    for m in methods:
        med = [value(by.get((m, n)), what="median") for n in scales]
        lo = [value(by.get((m, n))) - value(by.get((m, n)), what="std") for n in scales]
        hi = [value(by.get((m, n))) + value(by.get((m, n)), what="std") for n in scales]
        p = scaling_exponent(scales, med)
        ax.plot(scales, med, "o-", color=color[m], label=f"{m} (p={p:.2f})" if p is not None else m)
        ax.fill_between(scales, np.maximum(lo, 1e-3), hi, color=color[m], alpha=0.12)
    n_axis(ax, scales)
    ax.set_yscale("log")
    fps_lines(ax)
    ax.set_ylabel("total ms per frame (median, mean ± std band)")
    ax.set_title("Time against N")
    ax.legend(fontsize=7)
    return save(fig, out, CHART)


class Scaling(Study):
    """Time against N; measures nothing of its own."""

    name = "scaling"
    help = "time against N (log-log), fitted exponents, 60/24 fps budgets (uses table's data)"
    default = True
    data = "table"
    readme_links = ((CHART, "time against N"),)

    def section(self, res):
        by, scales = cells(res.rows["table"], "method", "n"), res.scales("table")
        rows = []
        for m in res.methods("table"):
            t = [by[(m, n)]["total_ms"]["median"] if (m, n) in by else None for n in scales]
            p = scaling_exponent(scales, t)
            fits = [largest_within(scales, t, budget) for _, budget in FPS_BUDGETS[::-1]]
            rows.append([m] + [ms(x) for x in t] + ["—" if p is None else f"{p:.2f}"]
                        + ["—" if f is None else n_label(f) for f in fits])
        head = (["Method"] + [n_label(n) for n in scales]
                + ["exponent p", "largest N ≤ 16.7 ms", "largest N ≤ 41.7 ms"])
        return "\n\n".join([
            "## 3. Time against N",
            "Median total ms per frame; p from a least-squares fit of log(ms) = a + p log(N) over the "
            "scales where the method converged (p = 1: linear cost). 60 fps = 16.7 ms, 24 fps = 41.7 ms.",
            md_table(head, rows),
            image(CHART, "Time against N"),
        ])

    def charts(self, res, out):
        return [chart(res, out)]


STUDY = Scaling()
