"""PNG charts of a results folder (matplotlib, Agg canvas, written atomically)."""
from __future__ import annotations

import math

import numpy as np

from ..atomic import atomic_open
from . import stats

TABLE = "table4.png"
CURVE_SUMMARY = "curves_summary.png"
SCALING = "scaling.png"
STABILITY = "stability.png"
GENERALIZATION = "generalization.png"
SIZE = "size.png"
PROFILE = "profile.png"
SPECTRUM = "spectrum.png"
FASTPATH = "fastpath.png"


def curve_name(n) -> str:
    """File name of the residual-against-time chart of one N."""
    return f"curves_n{n}.png"


def _figure(w, h, rows=1, cols=1):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False)


def _save(fig, out, name):
    fig.tight_layout()
    with atomic_open(f"{out}/{name}", "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    return name


def _colors(methods):
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {m: cmap(i % 10) for i, m in enumerate(methods)}


def _fps_lines(ax):
    for fps, budget in stats.FPS_BUDGETS:
        ax.axhline(budget, color="grey", ls="--", lw=0.8)
        ax.annotate(f"{fps} fps", (1.0, budget), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                    fontsize=8, color="grey")


def _n_axis(ax, scales):
    """Log-2 N axis ticked at the measured scales."""
    from matplotlib.ticker import NullLocator

    ax.set_xscale("log", base=2)
    ax.set_xticks(scales, [str(n) for n in scales])
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xlabel("N")


def _mean(cells, m, n, key="total_ms", what="mean"):
    c = cells.get((m, n))
    return c[key][what] if c and c[key]["count"] else math.nan


# ---------------------------------------------------------------- table / scaling

def table_chart(res, out, study="table", name=TABLE, title="Per-frame time (setup hatched) to rtol 1e-8"):
    """Grouped bars per N: mean total ms per method, the setup part hatched (log axis)."""
    rows = res.rows[study]
    methods = stats.ordered((r["method"] for r in rows), res.meta.get("methods", ()))
    scales = sorted({r["n"] for r in rows})
    cells = {k: stats.cell(v) for k, v in stats.group(rows, "method", "n").items()}
    colors = _colors(methods)
    fig, ax = _figure(1.6 + 1.3 * len(scales), 4.2)
    ax = ax[0, 0]
    width = 0.8 / max(len(methods), 1)
    x = np.arange(len(scales))
    for i, m in enumerate(methods):
        total = np.array([_mean(cells, m, n) for n in scales])
        setup = np.array([_mean(cells, m, n, "setup_ms") for n in scales])
        pos = x - 0.4 + (i + 0.5) * width
        ax.bar(pos, total, width, color=colors[m], label=m)
        ax.bar(pos, np.minimum(setup, total), width, color="none", edgecolor="black", hatch="///", lw=0)
    ax.set_yscale("log")
    ax.set_xticks(x, [str(n) for n in scales])
    ax.set_xlabel("N")
    ax.set_ylabel("ms per frame (mean)")
    ax.set_title(title)
    _fps_lines(ax)
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, out, name)


def scaling_chart(res, out):
    """log-log median total ms against N per method with fps budget lines and fitted exponents."""
    rows = res.rows["table"]
    methods = res.methods("table")
    scales = res.scales("table")
    cells = {k: stats.cell(v) for k, v in stats.group(rows, "method", "n").items()}
    colors = _colors(methods)
    fig, ax = _figure(6.5, 4.5)
    ax = ax[0, 0]
    for m in methods:
        med = [_mean(cells, m, n, what="median") for n in scales]
        lo = [_mean(cells, m, n) - _mean(cells, m, n, what="std") for n in scales]
        hi = [_mean(cells, m, n) + _mean(cells, m, n, what="std") for n in scales]
        p = stats.scaling_exponent(scales, med)
        ax.plot(scales, med, "o-", color=colors[m], label=f"{m} (p={p:.2f})" if p is not None else m)
        ax.fill_between(scales, np.maximum(lo, 1e-3), hi, color=colors[m], alpha=0.12)
    _n_axis(ax, scales)
    ax.set_yscale("log")
    _fps_lines(ax)
    ax.set_ylabel("total ms per frame (median, mean ± std band)")
    ax.set_title("Time against N")
    ax.legend(fontsize=7)
    return _save(fig, out, SCALING)


# ------------------------------------------------------------------------ curves

def curve_chart(res, out, n):
    """Residual against wall-clock time of every method on the representative frame of one N."""
    rows = [r for r in res.rows["curves"] if r["n"] == n]
    colors = _colors(res.methods("curves"))
    fig, ax = _figure(6.5, 4.2)
    ax = ax[0, 0]
    for r in rows:
        pts = np.array(r.get("curve") or [[math.nan, 0, math.nan]], dtype=float)
        ax.plot(pts[:, 0], pts[:, 2], color=colors[r["method"]], label=r["method"], lw=1.2)
    for tol in stats.TOLERANCES:
        ax.axhline(tol, color="grey", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall-clock ms (setup included)")
    ax.set_ylabel("||r_k|| / ||b||")
    ax.set_title(f"Residual against time, N={n}")
    ax.legend(fontsize=7)
    return _save(fig, out, curve_name(n))


def curve_summary_chart(res, out):
    """Time to 1e-3, 1e-6 and 1e-8 against N, one panel per tolerance."""
    rows = res.rows["curves"]
    methods, scales = res.methods("curves"), res.scales("curves")
    colors = _colors(methods)
    by = {(r["method"], r["n"]): r for r in rows}
    fig, axes = _figure(12, 3.8, 1, len(stats.TOLERANCES))
    for ax, tol in zip(axes[0], stats.TOLERANCES):
        for m in methods:
            t = [stats.time_to(by.get((m, n), {}).get("curve"), tol) for n in scales]
            ax.plot(scales, [math.nan if v is None else v for v in t], "o-", color=colors[m], label=m)
        _n_axis(ax, scales)
        ax.set_yscale("log")
        _fps_lines(ax)
        ax.set_ylabel("ms")
        ax.set_title(f"time to ||r||/||b|| ≤ {tol:g}")
    axes[0, 0].legend(fontsize=7)
    return _save(fig, out, CURVE_SUMMARY)


# --------------------------------------------------------------------- heat-maps

def _heatmap(ax, values, labels, rows, cols, cmap="viridis"):
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


def stability_chart(res, out):
    """Methods × stress cases: colour = log10 median iterations, red = failure with its code."""
    rows = res.rows["stability"]
    methods = res.methods("stability")
    cases = stats.ordered(r["case"] for r in rows)
    groups = stats.group(rows, "case", "method")
    values = np.full((len(cases), len(methods)), np.nan)
    labels = np.full(values.shape, "", dtype=object)
    for (i, case), (j, m) in ((a, b) for a in enumerate(cases) for b in enumerate(methods)):
        g = groups.get((case, m), [])
        fail = stats.first_failure(g)
        if g and not fail:
            values[i, j] = stats.summary(r["iterations"] for r in g)["median"]
            labels[i, j] = f"{values[i, j]:.0f}"
        else:
            labels[i, j] = fail or ""
    fig, ax = _figure(1.5 + 1.1 * len(methods), 1.2 + 0.42 * len(cases))
    im = _heatmap(ax[0, 0], values, labels, cases, methods)
    fig.colorbar(im, ax=ax[0, 0], label="log10 iterations")
    ax[0, 0].set_title("Stability map (red: failure)")
    return _save(fig, out, STABILITY)


def generalization_chart(res, out):
    """Train × eval distribution: log10 mean HTP iterations, annotated."""
    from .cases import EVAL_SETS, TRAIN_SETS

    rows = [r for r in res.rows["generalization"] if r.get("train")]
    groups = stats.group(rows, "train", "eval")
    values = np.full((len(TRAIN_SETS), len(EVAL_SETS)), np.nan)
    labels = np.full(values.shape, "", dtype=object)
    for (i, (tr, _)), (j, (ev, _)) in ((a, b) for a in enumerate(TRAIN_SETS) for b in enumerate(EVAL_SETS)):
        g = groups.get((tr, ev), [])
        c = stats.cell(g) if g else None
        if c and c["iterations"]["count"]:
            values[i, j] = c["iterations"]["mean"]
            labels[i, j] = f"{values[i, j]:.0f}" + (f" ✗{c['failed']}" if c["failed"] else "")
        elif c:
            labels[i, j] = c["failure"] or ""
    fig, ax = _figure(7.5, 3.6)
    im = _heatmap(ax[0, 0], values, labels, [t for _, t in TRAIN_SETS], [e for _, e in EVAL_SETS], "magma")
    fig.colorbar(im, ax=ax[0, 0], label="log10 mean PCG iterations")
    ax[0, 0].set_title("Generalization: train (rows) × eval (columns)")
    return _save(fig, out, GENERALIZATION)


# -------------------------------------------------------------------------- size

def size_chart(res, out):
    """Parameters against mean total ms (Pareto front joined) and against mean iterations."""
    from .report import size_summary, size_verdict

    summ = size_summary(res.rows["size"])
    front, enough = size_verdict(summ)
    fig, axes = _figure(11, 4.2, 1, 2)
    for ax, key, ylabel in ((axes[0, 0], "total", "mean total ms"), (axes[0, 1], "iters", "mean PCG iterations")):
        for label, s in summ.items():
            x, y = s["info"]["params"], s[key]
            ax.plot([x], [y], "o", color="tab:red" if label in front else "tab:blue")
            ax.annotate(label + (" ◀" if label == enough else ""), (x, y), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        if key == "total" and front:
            ax.plot([summ[k]["info"]["params"] for k in front], [summ[k]["total"] for k in front], "r--", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("parameters")
        ax.set_ylabel(ylabel)
    axes[0, 0].set_title("Pareto front (red) of parameters vs total time")
    axes[0, 1].set_title("Parameters vs iterations")
    return _save(fig, out, SIZE)


# ----------------------------------------------------------------------- profile

def profile_chart(res, out):
    """Loss and held-out SAI loss (top), held-out PCG iterations (bottom) against wall-clock minutes."""
    rows = res.rows["profile"]
    train = [r for r in rows if r.get("kind") == "train"]
    logged = [r for r in train if "loss" in r]
    evals = [r for r in train if r.get("pcg_iters") is not None]
    fig, axes = _figure(8, 6, rows=2)
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
    return _save(fig, out, PROFILE)


def _minutes_to_steps(logged):
    """(forward, inverse) interpolation between wall-clock minutes and steps of a log."""
    t = np.array([0.0] + [r["wall_s"] / 60 for r in logged])
    s = np.array([0.0] + [float(r["step"]) for r in logged])
    return (lambda x: np.interp(x, t, s)), (lambda y: np.interp(y, s, t))


def spectrum_chart(res, out):
    """Eigenvalues of M A per preconditioner (jittered strips, log axis) with κ in the labels."""
    spec = [r for r in res.rows["profile"] if r.get("kind") == "spectrum"]
    fig, ax = _figure(8, 1.2 + 0.9 * max(len(spec), 1))
    ax = ax[0, 0]
    rng = np.random.default_rng(0)
    for i, r in enumerate(spec):
        e = np.asarray(r["eigs"], dtype=float)
        pos = e[e > 0]
        ax.plot(pos, i + rng.uniform(-0.25, 0.25, pos.size), ".", ms=2, alpha=0.6)
        if (e <= 0).any():
            ax.annotate(f"{int((e <= 0).sum())} eigenvalues ≤ 0 not shown", (1.0, i), xycoords=("axes fraction", "data"),
                        ha="right", fontsize=7, color="tab:red")
    ax.set_yticks(range(len(spec)), [f"{r['method']} (κ={r['kappa']:.2g})" for r in spec])
    ax.set_xscale("log")
    ax.set_xlabel("eigenvalue of M A")
    ax.set_title(f"Spectrum of M A, N={spec[0]['n'] if spec else '?'}")
    return _save(fig, out, SPECTRUM)


# ------------------------------------------------------------------------ driver

def draw_all(res, out) -> list:
    """Every chart the folder's rows support; returns the file names written."""
    rows, names = res.rows, []
    if "table" in rows:
        names += [table_chart(res, out), scaling_chart(res, out)]
    if "curves" in rows:
        names += [curve_chart(res, out, n) for n in res.scales("curves")] + [curve_summary_chart(res, out)]
    if "stability" in rows:
        names.append(stability_chart(res, out))
    if "generalization" in rows:
        names.append(generalization_chart(res, out))
    if "size" in rows:
        names.append(size_chart(res, out))
    if "profile" in rows:
        names += [profile_chart(res, out), spectrum_chart(res, out)]
    if "fastpath" in rows:
        names.append(table_chart(res, out, "fastpath", FASTPATH, "Fast path: per-frame time (setup hatched)"))
    return names
