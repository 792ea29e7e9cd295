"""Paper Table 6 and the supplement grid: one model per training distribution on every eval set."""
from __future__ import annotations

import math

import numpy as np

from ...scenes.generator import make_frame
from ..aggregate import cells
from ..cases import Problem, held_out_frames, held_out_seeds
from ..markdown import image, its, md_table, ms, n_label, pm, ratio
from ..plotting import figure, heatmap, save
from .base import TRAINING, Size, Study, tag

CHART = "generalization.png"
TRAIN_SETS = (
    ("full", "Full"),
    ("no_closed", "Excl. closed barriers"),
    ("low_contrast", "Low contrast [5, 25]"),
    ("no_closed_low_contrast", "Excl. closed + low contrast"),
)
EVAL_SETS = (
    ("full", "Full / in-distribution"),
    ("closed_only", "Closed barriers only"),
    ("high_contrast", "High contrast (25, 100]"),
    ("closed_high", "Closed + high contrast"),
)
VARIANTS = ("cg_twolevel_const", "cg_twolevel_eig", "cg_twolevel_learned")   # no training per distribution
COMPLEMENT = {"full": "full", "closed_only": "no_closed", "high_contrast": "low_contrast",
              "closed_high": "no_closed_low_contrast"}


def eval_problems(name, n, count) -> list:
    """Test frames of one eval set of :data:`EVAL_SETS`."""
    if name == "closed_high":
        frames = [make_frame(n, s, "closed_only", contrast=(25.0, 100.0)) for s in held_out_seeds(count)]
    else:
        frames = held_out_frames(n, count, name)
    return [Problem(f, case=name) for f in frames]


def train_models(out, cfg, budget) -> dict:
    """One model of configuration ``cfg`` per training distribution of :data:`TRAIN_SETS`."""
    from ..training import trained_checkpoint

    return {name: trained_checkpoint(out, cfg, name, "cosine", budget) for name, _ in TRAIN_SETS}


def run(models, n, frames, extra, tick) -> list:
    """Every model (``{train set: checkpoint}``) and two-level variant on every eval set; CG + Jacobi as baseline."""
    from ..methods import resolve_method
    from ..runner import htp_options, run_method
    from ..training import model_info

    jac, htp = resolve_method("cg_jacobi"), resolve_method("cg_paper")
    rows = []
    for name, _ in EVAL_SETS:
        problems = eval_problems(name, n, frames)
        got = run_method(jac, problems, extra, tick=tick)
        rows += [tag(r, study="generalization", eval=name, train=None) for r in got]
        for variant in VARIANTS:
            got = run_method(resolve_method(variant), problems, extra, tick=tick)
            rows += [tag(r, study="generalization", eval=name, train=None, variant=variant) for r in got]
        for train_set, path in models.items():
            info = model_info(path)
            got = run_method(htp, problems, extra + htp_options(checkpoint=path), tick=tick)
            rows += [tag(r, study="generalization", eval=name, train=train_set, **info) for r in got]
    return rows


def _speedup(by, jac, tr, ev):
    c = by.get((tr, ev))
    return jac.get(ev, math.nan) / c["total_ms"]["mean"] if c and c["total_ms"]["count"] else math.nan


def _config_label(rows):
    """Architecture of the first HTP row's model, e.g. ``d=64, n_l=2, hw``."""
    r = next((r for r in rows if r.get("d")), None)
    return "?" if r is None else f"d={r['d']}, n_l={r['n_layers']}, {'hw' if r['highways'] else 'no-hw'}"


def chart(res, out) -> str:
    """Train × eval distribution: log10 mean HTP iterations, annotated."""
    by = cells([r for r in res.rows["generalization"] if r.get("train") and not r.get("variant")], "train", "eval")
    values = np.full((len(TRAIN_SETS), len(EVAL_SETS)), np.nan)
    labels = np.full(values.shape, "", dtype=object)
    for (i, (tr, _)), (j, (ev, _)) in ((a, b) for a in enumerate(TRAIN_SETS) for b in enumerate(EVAL_SETS)):
        c = by.get((tr, ev))
        if c and c["iterations"]["count"]:
            values[i, j] = c["iterations"]["mean"]
            labels[i, j] = f"{values[i, j]:.0f}" + (f" ✗{c['failed']}" if c["failed"] else "")
        elif c:
            labels[i, j] = c["failure"] or ""
    fig, ax = figure(7.5, 3.6)
    im = heatmap(ax[0, 0], values, labels, [t for _, t in TRAIN_SETS], [e for _, e in EVAL_SETS], "magma")
    fig.colorbar(im, ax=ax[0, 0], label="log10 mean PCG iterations")
    ax[0, 0].set_title("Generalization: train (rows) × eval (columns)")
    return save(fig, out, CHART)


def _variant_grid(res, evals, jac) -> list:
    """Rows of the two-level variants' table: iterations, Δ_OOD and speedup per eval set."""
    by = cells([r for r in res.rows["generalization"] if r.get("variant")], "variant", "eval")
    out = []
    for variant in VARIANTS:
        base = by.get((variant, "full"))
        row = [variant]
        for ev in evals:
            c = by.get((variant, ev))
            ok = c and c["total_ms"]["count"]
            delta = c["iterations"]["mean"] / base["iterations"]["mean"] if ok and base else math.nan
            row.append("—" if not ok else f"{pm(c['iterations'], its)} · Δ {delta:.2f} · "
                                          f"{ratio(jac.get(ev, math.nan) / c['total_ms']['mean'])}"
                       + (f" ✗{c['failed']}" if c["failed"] else ""))
        out.append(row)
    return out


class Generalization(Study):
    """Trains one model per training distribution; CG + HTP on every eval distribution."""

    name = "generalization"
    help = "paper Table 6 + grid: trains 4 models (--train-budget-minutes each; 0: only the untrained rows)"
    sizes = (Size("gen_n", 4096, 256, "N of the generalization study"),
             Size("gen_frames", 20, 2, "frames per generalization eval set")) + TRAINING
    readme_links = ((CHART, "generalization"),)

    def meta(self, settings):
        return {"generalization": {"n": settings["gen_n"], "frames": settings["gen_frames"]}}

    def expected_solves(self, ctx):
        trained = len(TRAIN_SETS) if ctx.settings["train_minutes"] > 0 else 0
        return len(EVAL_SETS) * (1 + len(VARIANTS) + trained) * ctx.settings["gen_frames"]

    def measure(self, ctx, tick):
        models = train_models(ctx.out, ctx.config, ctx.budget) if ctx.settings["train_minutes"] > 0 else {}
        return run(models, ctx.settings["gen_n"], ctx.settings["gen_frames"], ctx.extra, tick)

    def section(self, res):
        rows = [r for r in res.rows["generalization"] if not r.get("variant")]
        by = cells(rows, "train", "eval")
        jac = {ev: c["total_ms"]["mean"] for (tr, ev), c in by.items() if tr is None}
        g = res.meta.get("generalization", {})
        names = dict(EVAL_SETS)
        evals = [e for e, _ in EVAL_SETS if (None, e) in by]
        t6 = []
        for ev in evals:
            tr = COMPLEMENT[ev]
            c, j = by.get((tr, ev)), by[(None, ev)]
            t6.append([names[ev], ms(jac[ev]), its(j["iterations"]["mean"]), tr,
                       pm(c["iterations"], its) if c else "—", ms(c["total_ms"]["mean"]) if c else "—",
                       ratio(_speedup(by, jac, tr, ev))])
        grid = []
        for tr, label in TRAIN_SETS:
            base = by.get((tr, "full"))
            row = [label]
            for ev in evals:
                c = by.get((tr, ev))
                delta = c["iterations"]["mean"] / base["iterations"]["mean"] if c and base else math.nan
                row.append("—" if not c else f"{pm(c['iterations'], its)} · Δ {delta:.2f} · "
                                              f"{ratio(_speedup(by, jac, tr, ev))}")
            grid.append(row)
        variants = [
            "Two-level variants on the same frames (nothing trained per distribution; `learned` is the shipped "
            "coarse network, trained on Full): mean ± std iterations · Δ_OOD against the variant's own Full "
            "column · speedup against Jacobi:",
            md_table(["Variant"] + [names[e] for e in evals], _variant_grid(res, evals, jac))]
        head = [f"## 5. Generalization (paper Table 6)\n\nN = {n_label(g.get('n', 0))}, {g.get('frames', '?')} "
                "frames per eval set; speedup = Jacobi mean total ms / mean total ms on the same frames."]
        if not any(tr for tr, _ in by):
            return "\n\n".join(head + ["No HTP models trained in this run (`--train-budget-minutes 0`)."] + variants)
        return "\n\n".join(head + [
            f"CG + HTP with one model per training distribution ({_config_label(rows)}, cosine loss). Training "
            f"budget: {res.meta.get('budget', {}).get('text', '?')}.",
            "Each eval set against the model trained on its complement (the paper's held-out protocol):",
            md_table(["Eval distribution", "Jacobi ms", "Jacobi its", "HTP trained on", "HTP its",
                      "HTP ms", "speedup"], t6),
            "Full grid (supplement Table 8): mean ± std iterations · Δ_OOD (iterations / the same model's "
            "Full column) · speedup against Jacobi:",
            md_table(["Train \\ eval"] + [names[e] for e in evals], grid),
            image(CHART, "Generalization grid")] + variants)

    def charts(self, res, out):
        trained = any(r.get("train") for r in res.rows["generalization"])
        return [chart(res, out)] if trained else []


STUDY = Generalization()
