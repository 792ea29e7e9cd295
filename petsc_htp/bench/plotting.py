"""Chart helpers the studies share: figure, atomic PNG save, colours, axes, heat-map, time bars."""
from __future__ import annotations

import numpy as np

from ..atomic import atomic_open
from .aggregate import FPS_BUDGETS, cells, value


def figure(w, h, rows=1, cols=1):
    """A matplotlib figure on the Agg canvas and its axes (2-D array)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False)


def save(fig, out, name) -> str:
    """Write ``fig`` as PNG ``name`` into folder ``out`` atomically; return ``name``."""
    fig.tight_layout()
    with atomic_open(f"{out}/{name}", "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    return name


def colors(methods) -> dict:
    """A tab10 colour per method."""
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {m: cmap(i % 10) for i, m in enumerate(methods)}


def fps_lines(ax):
    """Dashed lines at the 24 and 60 fps frame budgets."""
    for fps, budget in FPS_BUDGETS:
        ax.axhline(budget, color="grey", ls="--", lw=0.8)
        ax.annotate(f"{fps} fps", (1.0, budget), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                    fontsize=8, color="grey")


def n_axis(ax, scales):
    """Log-2 N axis ticked at the measured scales."""
    from matplotlib.ticker import NullLocator

    ax.set_xscale("log", base=2)
    ax.set_xticks(scales, [str(n) for n in scales])
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xlabel("N")


def heatmap(ax, values, labels, rows, cols, cmap="viridis"):
    """Annotated heat-map of log10(values); NaN cells drawn red with their label."""
    from matplotlib import colormaps

    data = np.log10(np.where(np.isfinite(values) & (values > 0), values, np.nan))
    cm = colormaps[cmap].with_extremes(bad="#e06060")
    im = ax.imshow(np.ma.masked_invalid(data), cmap=cm, aspect="auto")
    for (i, j), text in np.ndenumerate(labels):
        light = np.isnan(data[i, j]) or im.norm(data[i, j]) > 0.6
        ax.text(j, i, text, ha="center", va="center", fontsize=7, color="black" if light else "white")
    ax.set_xticks(range(len(cols)), cols, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(len(rows)), rows, fontsize=8)
    return im


def _grouped(methods, groups, w, h) -> tuple:
    """A figure for grouped bars: (figure, axes, a colour per method, bar width, group positions)."""
    fig, ax = figure(w, h)
    return fig, ax[0, 0], colors(methods), 0.8 / max(len(methods), 1), np.arange(groups)


def time_bars(res, out, study, name, title) -> str:
    """Grouped bars per N: mean total ms per method of ``study``'s rows, the setup part hatched (log axis)."""
    methods, scales = res.methods(study), res.scales(study)
    by = cells(res.rows[study], "method", "n")
    fig, ax, color, width, x = _grouped(methods, len(scales), 1.6 + 1.3 * len(scales), 4.2)
    for i, m in enumerate(methods):
        total = np.array([value(by.get((m, n))) for n in scales])
        setup = np.array([value(by.get((m, n)), "setup_ms") for n in scales])
        pos = x - 0.4 + (i + 0.5) * width
        ax.bar(pos, total, width, color=color[m], label=m)
        ax.bar(pos, np.minimum(setup, total), width, color="none", edgecolor="black", hatch="///", lw=0)
    ax.set_yscale("log")
    ax.set_xticks(x, [str(n) for n in scales])
    ax.set_xlabel("N")
    ax.set_ylabel("ms per frame (mean)")
    ax.set_title(title)
    fps_lines(ax)
    ax.legend(fontsize=7, ncol=2)
    return save(fig, out, name)


def foreign_bars(rows, methods, out, name) -> str:
    """Grouped bars per case (and N): median setup + solve ms of each method, failures left blank (log axis)."""
    by = cells(rows, "case", "n", "method")
    keys = list(dict.fromkeys((r["case"], r["n"]) for r in rows))
    fig, ax, color, width, x = _grouped(methods, len(keys), 2.0 + 0.9 * len(keys), 4.4)
    for i, m in enumerate(methods):
        total = np.array([value(by.get((c, n, m)), "total_ms", "median") for c, n in keys])
        ax.bar(x - 0.4 + (i + 0.5) * width, total, width, color=color[m], label=m)
    ax.set_yscale("log")
    ax.set_xticks(x, [f"{c}\n{n}" for c, n in keys], rotation=30, ha="right", fontsize=7)
    ax.set_ylabel("setup + solve ms (median)")
    ax.set_title("Matrices from other programs: one solve, fresh KSP")
    ax.legend(fontsize=7, ncol=2)
    return save(fig, out, name)
