"""Model size: one change at a time around the base configuration, each model trained the same way."""
from __future__ import annotations

import dataclasses
import math

from ..aggregate import cells, group, pareto_front, summary
from ..cases import table_problems
from ..markdown import image, its, md_table, ms, n_label
from ..plotting import figure, save
from .base import TRAINING, Size, Study, tag

CHART = "size.png"
NEAR_BEST = 0.10     # "smallest sufficient model": within 10 % of the fastest total time


def configs(base):
    """(configuration, loss) pairs: the base, then one change at a time (d, n_l, highways, loss)."""
    from ..training import model_key

    out = [(base, "cosine")]
    out += [(dataclasses.replace(base, d=d), "cosine") for d in (32, 64, 128)]
    out += [(dataclasses.replace(base, n_layers=k), "cosine") for k in (1, 2, 3)]
    out += [(dataclasses.replace(base, highways=not base.highways), "cosine"), (base, "sai")]
    keys = {}
    for cfg, loss in out:
        keys.setdefault(model_key(cfg, "full", loss), (cfg.validate(), loss))
    return list(keys.values())


def train_models(out, base, budget) -> list:
    """``(configuration, loss, checkpoint)`` of every :func:`configs` model, trained on the full distribution."""
    from ..training import trained_checkpoint

    return [(cfg, loss, trained_checkpoint(out, cfg, "full", loss, budget)) for cfg, loss in configs(base)]


def run(models, base, scales, frames, extra, tick) -> list:
    """CG + HTP with every ``(configuration, loss, checkpoint)`` on held-out frames."""
    from ..methods import resolve_method
    from ..runner import htp_options, run_method
    from ..training import label, model_info

    htp = resolve_method("cg_paper")
    problems = table_problems(scales, frames)
    rows = []
    for cfg, loss, path in models:
        got = run_method(htp, problems, extra + htp_options(checkpoint=path), tick=tick)
        info = model_info(path)
        rows += [tag(r, study="size", config=label(cfg, loss), base=cfg == base and loss == "cosine", **info)
                 for r in got]
    return rows


def summarise(rows) -> dict:
    """Per configuration: first row (its model info), per-N cells, mean total ms and iterations."""
    out = {}
    for (label,), rows_of in group(rows, "config").items():
        per_n = {n: c for (n,), c in cells(rows_of, "n").items()}
        total = [c["total_ms"]["mean"] for c in per_n.values()]
        out[label] = {"info": rows_of[0], "per_n": per_n,
                      "total": float(sum(total) / len(total)) if total else math.nan,
                      "iters": summary(r["iterations"] for r in rows_of if r.get("ok"))["mean"]}
    return out


def verdict(summ):
    """(labels on the params/total-ms Pareto front, the smallest configuration within 10 % of the fastest)."""
    labels = list(summ)
    pts = [(summ[k]["info"]["params"], summ[k]["total"]) for k in labels]
    front = [labels[i] for i in pareto_front(pts)]
    finite = [t for _, t in pts if math.isfinite(t)]
    if not finite:
        return front, None
    near = [k for k in labels if summ[k]["total"] <= (1 + NEAR_BEST) * min(finite)]
    return front, min(near, key=lambda k: summ[k]["info"]["params"])


def chart(res, out) -> str:
    """Parameters against mean total ms (Pareto front joined) and against mean iterations."""
    summ = summarise(res.rows["size"])
    front, enough = verdict(summ)
    fig, axes = figure(11, 4.2, 1, 2)
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
    return save(fig, out, CHART)


class ModelSize(Study):
    """Trains about seven models; CG + HTP with each on held-out frames."""

    name = "size"
    help = "model size sweep (d, n_l, highways, loss) with a Pareto chart: trains ~7 models"
    sizes = TRAINING + (Size("size_scales", [2048, 4096, 8192], [256], "N of the size study"),
                        Size("size_frames", 5, 1, "frames per N in the size study"))
    readme_links = ((CHART, "model size"),)

    def meta(self, settings):
        return {"size": {"scales": settings["size_scales"], "frames": settings["size_frames"]}}

    def expected_solves(self, ctx):
        return len(configs(ctx.config)) * len(ctx.settings["size_scales"]) * ctx.settings["size_frames"]

    def measure(self, ctx, tick):
        models = train_models(ctx.out, ctx.config, ctx.budget)
        return run(models, ctx.config, ctx.settings["size_scales"], ctx.settings["size_frames"], ctx.extra, tick)

    def section(self, res):
        summ = summarise(res.rows["size"])
        scales = res.scales("size")
        front, enough = verdict(summ)
        table = []
        for label, s in summ.items():
            info = s["info"]
            row = [f"{ms(c['inference_ms']['mean'])} / {its(c['iterations']['mean'])} / {ms(c['total_ms']['mean'])}"
                   if (c := s["per_n"].get(n)) and c["total_ms"]["count"] else f"✗ {c['failure'] if c else '—'}"
                   for n in scales]
            mark = (" (base)" if info.get("base") else "") + (" ★" if label in front else "")
            table.append([label + mark, f"{info['params']:,}", str(info.get("train_steps")),
                          f"{(info.get('train_wall_s') or 0) / 60:.1f}"] + row + [ms(s["total"])])
        head = (["Configuration", "params", "train steps", "train min"]
                + [f"N={n_label(n)}: infer ms / its / total ms" for n in scales] + ["mean total ms"])
        budget = res.meta.get("budget", {}).get("text", "?")
        return "\n\n".join([
            "## 6. Model size",
            "One change at a time around the base configuration (width d, depth n_l, highways, loss), each "
            f"model trained on the full distribution with the same budget ({budget}); "
            f"CG + HTP on {res.meta.get('size', {}).get('frames', '?')} held-out frames per N. Inference is "
            "the network setup inside KSPSetUp; total = setup + solve. ★: on the Pareto front of parameters "
            "against mean total ms.",
            md_table(head, table),
            f"Pareto front (parameters vs mean total ms): {'; '.join(f'`{k}`' for k in front) or '—'}. Smallest "
            f"configuration within {NEAR_BEST:.0%} of the fastest mean total time: **{enough or '—'}**.",
            image(CHART, "Model size Pareto chart"),
        ])

    def charts(self, res, out):
        return [chart(res, out)]

    def readme(self, res, prefix):
        summ = summarise(res.rows["size"])
        front, enough = verdict(summ)
        base = next((k for k, v in summ.items() if v["info"].get("base")), "?")
        return (f"**Model size** (section 6 of the report; {res.meta.get('budget', {}).get('text', '?')}): "
                f"on the Pareto front of parameters against mean total ms: "
                f"{', '.join(f'`{k}`' for k in front) or '—'}; "
                f"smallest configuration within {NEAR_BEST:.0%} of the fastest: `{enough or '—'}`; "
                f"the base (shipped) configuration: `{base}`.")


STUDY = ModelSize()
