"""``report.md``: one Markdown section per study, built only from the raw rows and ``meta.json``.

The same rows always give the same text, so ``--report-only DIR`` reproduces
a report byte for byte; :func:`table4_section` is also what ``--readme``
puts into README.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from . import charts, stats, store
from .cases import EVAL_SETS, STRESS, TRAIN_SETS
from .tables import its, md_table, missing, ms, n_label, pm, ratio, sci, tol

COMPLEMENT = {"full": "full", "closed_only": "no_closed", "high_contrast": "low_contrast",
              "closed_high": "no_closed_low_contrast"}
NEAR_BEST = 0.10     # "smallest sufficient model": within 10 % of the fastest total time


@dataclass
class Results:
    """A results folder: ``meta.json`` and the rows of every study that ran."""

    meta: dict
    rows: dict

    def methods(self, study) -> list:
        """Method names of a study's rows, in the order the run listed them."""
        return stats.ordered((r["method"] for r in self.rows.get(study, [])), self.meta.get("methods", ()))

    def scales(self, study) -> list:
        """Sorted distinct N of a study's rows."""
        return sorted({r["n"] for r in self.rows.get(study, []) if r.get("n")})


def load(out) -> Results:
    """Read ``meta.json`` and every ``<study>.jsonl`` of a results folder."""
    if not (Path(out) / store.META).is_file():
        raise ValueError(f"{out} is not a results folder (no {store.META})")
    rows = {s: store.read_jsonl(store.study_path(out, s)) for s in store.STUDIES}
    return Results(store.read_json(f"{out}/{store.META}"), {s: r for s, r in rows.items() if r})


def _image(name, title, prefix=""):
    return f"![{title}]({prefix}{name})"


# ------------------------------------------------------------------------ header

def header(res) -> str:
    """Title, machine, software, protocol and the command that produced the folder."""
    m = res.meta
    mach = m.get("machine", {})
    ck = m.get("checkpoint") or {}
    lines = [
        "# petsc_htp benchmark",
        "",
        f"- Date: {m.get('date', '?')}; commit `{m.get('commit') or 'unknown'}`",
        f"- Machine: {mach.get('cpu', '?')} ({mach.get('cores', '?')} cores), {mach.get('platform', '?')}",
        "- Software: " + ", ".join(f"{k} {v}" for k, v in sorted(m.get("versions", {}).items())),
        "- Threads: " + ", ".join(f"{k}={v}" for k, v in sorted(m.get("threads", {}).items())),
        f"- HTP checkpoint: `{ck.get('path', 'none')}` (sha256 {ck.get('sha256', '—')}); "
        f"HTP device {m.get('device', 'auto')}",
        f"- Command: `petsc-htp bench {' '.join(m.get('argv', []))}`",
        "- Studies: " + ", ".join(f"{s} ({m['study_s'][s]:.0f} s)" for s in m.get("studies", ())
                                  if s in m.get("study_s", {})),
        "",
        "Protocol: every method solves the same held-out test frames (`load_dataset(N, \"test\")`) of the "
        f"singular Neumann multiphase Poisson problem from x0 = 0 to relative residual {tol(m.get('rtol', 1e-8))} "
        "in the unpreconditioned 2-norm (`options/common.opts`), at most "
        f"{m.get('max_it', '?')} iterations. PETSc methods are the options files in `options/`, each loaded "
        "under its own prefix into a fresh KSP; setup is KSPSetUp + PCSetUpOnBlocks (inference, AMG setup "
        "or factorisation), solve is KSPSolve. `pyamg` is pyamg's classical Ruge–Stüben AMG (one V-cycle) "
        "preconditioning a NumPy CG on the mean-projected rhs, a CPU reference. One warm-up solve per "
        "(method, N) is excluded. A run counts as failed on a DIVERGED_* reason, an exception, a NaN, or a "
        "true residual ||b - A x|| / ||b|| (constant null-space part removed) above 10 × rtol; failed "
        "frames are left out of the means and counted.",
    ]
    if m.get("quick"):
        lines += ["", "**Quick run** (`--quick`): CI-sized scales, frames and budgets; not for comparison."]
    return "\n".join(lines)


# ---------------------------------------------------------------- 1. Table 4

def _cells(res, study):
    return {k: stats.cell(v) for k, v in stats.group(res.rows[study], "method", "n").items()}


def _fastest(cells, methods, n):
    best = [(c["total_ms"]["mean"], m) for m in methods if (c := cells.get((m, n))) and not c["failed"]
            and c["total_ms"]["count"]]
    return min(best)[1] if best else None


def _main_cell(c, bold):
    if c is None:
        return "—"
    if not c["total_ms"]["count"]:
        return f"✗ {c['failure']}"
    text = f"{ms(c['total_ms']['mean'])} ({its(c['iterations']['mean'])})"
    text = f"**{text}**" if bold else text
    return text + (f" ✗{c['failed']}/{c['frames']} {c['failure']}" if c["failed"] else "")


def table4_body(res, prefix="") -> str:
    """The Table-4 tables (time and iterations per method and N, setup/solve split) and chart."""
    cells, methods, scales = _cells(res, "table"), res.methods("table"), res.scales("table")
    frames = res.meta.get("frames", "?")
    head = ["Method"] + [n_label(n) for n in scales]
    main = [[m] + [_main_cell(cells.get((m, n)), m == _fastest(cells, methods, n)) for n in scales]
            for m in methods]
    split = [[m] + [f"{ms(c['setup_ms']['median'])} + {ms(c['solve_ms']['median'])}"
                    if (c := cells.get((m, n))) else "—" for n in scales] for m in methods]
    return "\n\n".join([
        f"Per-frame time to rtol {tol(res.meta.get('rtol', 1e-8))}: mean of setup + solve in ms over {frames} "
        "held-out frames per N, mean PCG iterations in parentheses; **bold**: fastest method without "
        "failures at that N; ✗k/F: frames that failed (reason).",
        md_table(head, main),
        "Setup + solve split (median ms: setup + solve):",
        md_table(head, split),
        _image(charts.TABLE, "Time per frame", prefix),
    ])


def table4_section(res) -> str:
    """Section 1 with the variability tables of the supplement."""
    cells, methods, scales = _cells(res, "table"), res.methods("table"), res.scales("table")
    head = ["Method"] + [n_label(n) for n in scales]
    total = [[m] + [f"{ms(c['total_ms']['median'])}; {pm(c['total_ms'], ms)}" if (c := cells.get((m, n)))
                    else "—" for n in scales] for m in methods]
    iters = [[m] + [pm(c["iterations"], its) if (c := cells.get((m, n))) else "—" for n in scales]
             for m in methods]
    worst = [[m, sci(max((v for n in scales if (m, n) in cells and not missing(v := cells[(m, n)]["relres_max"])),
                         default=math.nan))] for m in methods]
    return "\n\n".join([
        "## 1. Time per frame (paper Table 4)",
        table4_body(res),
        "Total ms per frame, median; mean ± std:",
        md_table(head, total),
        "PCG iterations, mean ± std (supplement Table 7):",
        md_table(head, iters),
        "Largest true relative residual among converged frames:",
        md_table(["Method", "max ||b - A x|| / ||b|| (null-space part removed)"], worst),
    ])


# ------------------------------------------------------------- 2. accuracy

def curve_section(res) -> str:
    """Time to 1e-3, 1e-6, 1e-8 per method and N (from the KSP monitor), with the curve charts."""
    parts = ["## 2. Speed against accuracy",
             "Residual ||r_k|| / ||b|| against wall-clock time (setup included, clock started before "
             "KSPSetUp; KSP monitor timestamps) on the first held-out frame of every N. Time in ms to "
             "reach each tolerance (— never reached):"]
    groups = stats.group(res.rows["curves"], "n")
    for n in res.scales("curves"):
        by_method = {r["method"]: r for r in groups[(n,)]}
        rows = [[m] + [ms(stats.time_to(r.get("curve"), tol)) for tol in stats.TOLERANCES]
                + [its(r.get("iterations")) if r.get("ok") else f"✗ {stats.first_failure([r])}"]
                for m in res.methods("curves") if (r := by_method.get(m))]
        parts += [f"N = {n_label(n)} (seed {groups[(n,)][0].get('seed')}):",
                  md_table(["Method"] + [tol(t) for t in stats.TOLERANCES] + ["iterations"], rows),
                  _image(charts.curve_name(n), f"Residual against time, N={n}")]
    parts.append(_image(charts.CURVE_SUMMARY, "Time to tolerance against N"))
    return "\n\n".join(parts)


# ------------------------------------------------------------------ 3. scaling

def scaling_section(res) -> str:
    """Median total ms per N, fitted exponent and the largest N inside the 60 and 24 fps budgets."""
    cells, scales = _cells(res, "table"), res.scales("table")
    rows = []
    for m in res.methods("table"):
        t = [cells[(m, n)]["total_ms"]["median"] if (m, n) in cells else None for n in scales]
        p = stats.scaling_exponent(scales, t)
        fits = [stats.largest_within(scales, t, budget) for _, budget in stats.FPS_BUDGETS[::-1]]
        rows.append([m] + [ms(x) for x in t] + ["—" if p is None else f"{p:.2f}"]
                    + ["—" if f is None else n_label(f) for f in fits])
    head = ["Method"] + [n_label(n) for n in scales] + ["exponent p", "largest N ≤ 16.7 ms", "largest N ≤ 41.7 ms"]
    return "\n\n".join([
        "## 3. Time against N",
        "Median total ms per frame; p from a least-squares fit of log(ms) = a + p log(N) over the "
        "scales where the method converged (p = 1: linear cost). 60 fps = 16.7 ms, 24 fps = 41.7 ms.",
        md_table(head, rows),
        _image(charts.SCALING, "Time against N"),
    ])


# ---------------------------------------------------------------- 4. stability

def _stability_cell(rows):
    failure = stats.first_failure(rows)
    if failure:
        return f"✗ {failure}"
    return its(stats.summary(r["iterations"] for r in rows)["median"])


def _inconsistent_note(rows):
    """What the converged iterations of the inconsistent-rhs case mean."""
    true = stats.summary(r.get("relres") for r in rows if r["case"] == "inconsistent rhs" and r.get("ok"))
    return ("Inconsistent rhs: methods converge on the residual with the constant (null-space) part "
            f"removed; the true ||b - A x|| / ||b|| stays at {sci(true['median'])} (median), the constant "
            "part of b that no x can match.") if true["count"] else ""


def stability_section(res) -> str:
    """Methods × stress cases: median iterations or the failure, then every failure's details."""
    rows = res.rows["stability"]
    groups = stats.group(rows, "case", "method")
    methods = res.methods("stability")
    meta = res.meta.get("stress", {})
    described = dict(STRESS)
    table = [[case] + [_stability_cell(groups[(case, m)]) if (case, m) in groups else "—" for m in methods]
             for case in stats.ordered((r["case"] for r in rows), described)]
    fails = [[r["method"], r["case"], n_label(r["n"]), str(r.get("seed")), r.get("failure") or "",
              its(r.get("iterations")), sci(r.get("relres_proj")), (r.get("error") or "")[:120]]
             for r in rows if not r.get("ok")]
    parts = [
        "## 4. Stability map",
        f"Median iterations over {meta.get('frames', '?')} frame(s) per case at N = "
        f"{n_label(meta.get('n', 0))} (large N = {n_label(meta.get('large_n', 0))}, odd N = "
        f"{n_label(meta.get('odd_n', 0))}); ✗ marks a case where at least one frame failed, with the "
        "first failure: max it (DIVERGED_MAX_IT), breakdown, indef. PC, NaN/Inf, exception, true res. "
        "(converged but ||b - A x|| above 10 × rtol after removing the null-space part). No warm-up.",
        md_table(["Case"] + methods, table),
        _inconsistent_note(rows),
        "Cases: " + "; ".join(f"**{k}**: {v}" for k, v in STRESS) + ".",
        _image(charts.STABILITY, "Stability map"),
    ]
    if fails:
        parts += ["Failures:", md_table(["Method", "Case", "N", "seed", "failure", "its", "true res.", "error"],
                                        fails, left=2)]
    return "\n\n".join(p for p in parts if p)


# ----------------------------------------------------------- 5. generalization

def _gen_stats(rows):
    cells = {k: stats.cell(v) for k, v in stats.group(rows, "train", "eval").items()}
    jac = {ev: cells[(None, ev)]["total_ms"]["mean"] for (tr, ev) in cells if tr is None}
    return cells, jac


def _speedup(cells, jac, tr, ev):
    c = cells.get((tr, ev))
    return jac.get(ev, math.nan) / c["total_ms"]["mean"] if c and c["total_ms"]["count"] else math.nan


def _config_label(rows):
    """Architecture of the first HTP row's model, e.g. ``d=64, n_l=2, hw``."""
    r = next((r for r in rows if r.get("d")), None)
    return "?" if r is None else f"d={r['d']}, n_l={r['n_layers']}, {'hw' if r['highways'] else 'no-hw'}"


def generalization_section(res) -> str:
    """Paper Table 6 (model trained on the eval set's complement) and the full train × eval grid."""
    rows = res.rows["generalization"]
    cells, jac = _gen_stats(rows)
    g = res.meta.get("generalization", {})
    names = dict(EVAL_SETS)
    evals = [e for e, _ in EVAL_SETS if (None, e) in cells]
    t6 = []
    for ev in evals:
        tr = COMPLEMENT[ev]
        c, j = cells.get((tr, ev)), cells[(None, ev)]
        t6.append([names[ev], ms(jac[ev]), its(j["iterations"]["mean"]), tr,
                   pm(c["iterations"], its) if c else "—", ms(c["total_ms"]["mean"]) if c else "—",
                   ratio(_speedup(cells, jac, tr, ev))])
    grid = []
    for tr, label in TRAIN_SETS:
        base = cells.get((tr, "full"))
        row = [label]
        for ev in evals:
            c = cells.get((tr, ev))
            delta = c["iterations"]["mean"] / base["iterations"]["mean"] if c and base else math.nan
            row.append("—" if not c else f"{pm(c['iterations'], its)} · Δ {delta:.2f} · "
                                          f"{ratio(_speedup(cells, jac, tr, ev))}")
        grid.append(row)
    return "\n\n".join([
        "## 5. Generalization (paper Table 6)",
        f"N = {n_label(g.get('n', 0))}, {g.get('frames', '?')} frames per eval set, CG + HTP with one model "
        f"per training distribution ({_config_label(rows)}, cosine loss). Training budget: "
        f"{res.meta.get('budget', {}).get('text', '?')}. Speedup = Jacobi mean total ms / HTP mean total "
        "ms on the same frames.",
        "Each eval set against the model trained on its complement (the paper's held-out protocol):",
        md_table(["Eval distribution", "Jacobi ms", "Jacobi its", "HTP trained on", "HTP its",
                  "HTP ms", "speedup"], t6),
        "Full grid (supplement Table 8): mean ± std iterations · Δ_OOD (iterations / the same model's "
        "Full column) · speedup against Jacobi:",
        md_table(["Train \\ eval"] + [names[e] for e in evals], grid),
        _image(charts.GENERALIZATION, "Generalization grid"),
    ])


# --------------------------------------------------------------------- 6. size

def size_summary(rows):
    """Per configuration: first row (its model info), per-N cells, mean total ms and iterations."""
    out = {}
    for (label,), group in stats.group(rows, "config").items():
        per_n = {n: stats.cell(g) for (n,), g in stats.group(group, "n").items()}
        total = [c["total_ms"]["mean"] for c in per_n.values()]
        out[label] = {"info": group[0], "per_n": per_n,
                      "total": float(sum(total) / len(total)) if total else math.nan,
                      "iters": stats.summary(r["iterations"] for r in group if r.get("ok"))["mean"]}
    return out


def size_verdict(summary):
    """(labels on the params/total-ms Pareto front, the smallest config within 10 % of the fastest)."""
    labels = list(summary)
    pts = [(summary[k]["info"]["params"], summary[k]["total"]) for k in labels]
    front = [labels[i] for i in stats.pareto_front(pts)]
    finite = [t for _, t in pts if math.isfinite(t)]
    if not finite:
        return front, None
    near = [k for k in labels if summary[k]["total"] <= (1 + NEAR_BEST) * min(finite)]
    return front, min(near, key=lambda k: summary[k]["info"]["params"])


def size_section(res) -> str:
    """Parameters, inference, iterations and total time per configuration and N; the Pareto verdict."""
    rows = res.rows["size"]
    summ = size_summary(rows)
    scales = res.scales("size")
    front, enough = size_verdict(summ)
    table = []
    for label, s in summ.items():
        info = s["info"]
        cells = [f"{ms(c['inference_ms']['mean'])} / {its(c['iterations']['mean'])} / {ms(c['total_ms']['mean'])}"
                 if (c := s["per_n"].get(n)) and c["total_ms"]["count"] else f"✗ {c['failure'] if c else '—'}"
                 for n in scales]
        mark = (" (base)" if info.get("base") else "") + (" ★" if label in front else "")
        table.append([label + mark, f"{info['params']:,}", str(info.get("train_steps")),
                      f"{(info.get('train_wall_s') or 0) / 60:.1f}"] + cells + [ms(s["total"])])
    head = (["Configuration", "params", "train steps", "train min"]
            + [f"N={n_label(n)}: infer ms / its / total ms" for n in scales] + ["mean total ms"])
    return "\n\n".join([
        "## 6. Model size",
        "One change at a time around the base configuration (width d, depth n_l, highways, loss), each "
        f"model trained on the full distribution with the same budget ({res.meta.get('budget', {}).get('text', '?')}); "
        f"CG + HTP on {res.meta.get('size', {}).get('frames', '?')} held-out frames per N. Inference is "
        "the network setup inside KSPSetUp; total = setup + solve. ★: on the Pareto front of parameters "
        "against mean total ms.",
        md_table(head, table),
        f"Pareto front (parameters vs mean total ms): {'; '.join(f'`{k}`' for k in front) or '—'}. Smallest "
        f"configuration within {NEAR_BEST:.0%} of the fastest mean total time: **{enough or '—'}**.",
        _image(charts.SIZE, "Model size Pareto chart"),
    ])


# ------------------------------------------------------------------ 7. profile

def _train_summary(train):
    logged = [r for r in train if "loss" in r]
    evals = [r for r in train if r.get("pcg_iters") is not None]
    last = train[-1] if train else {}
    best = min(evals, key=lambda r: r["pcg_iters"]) if evals else None
    return (f"{last.get('step', 0)} steps in {last.get('wall_s', 0) / 60:.1f} min; loss "
            f"{logged[0]['loss']:.4g} → {logged[-1]['loss']:.4g}; " if logged else "no loss rows; ") + (
        f"held-out PCG iterations {_its_at(evals[0])} → {_its_at(evals[-1])} "
        f"(best {_its_at(best)} at step {best['step']})" if evals else "no held-out evaluations")


def _its_at(row):
    return f"{row['pcg_iters']}" + (f" at N={row['heldout_n']}" if row.get("heldout_n") else "")


def profile_section(res) -> str:
    """Training profile summary and the spectrum table with condition numbers."""
    rows = res.rows["profile"]
    kinds = stats.group(rows, "kind")
    source = kinds.get(("source",), [{}])[0]
    train = kinds.get(("train",), [])
    base = {f"{r['method']} (N={r['n']})": r["iterations"] for r in kinds.get(("baseline",), [])}
    spec = kinds.get(("spectrum",), [])
    k0 = spec[0]["kappa"] if spec else math.nan
    table = [[r["method"], sci(r["kappa"]), ratio(k0 / r["kappa"]), f"{r['eigs'][0]:.3g}", f"{r['eigs'][-1]:.3g}",
              "yes" if r["indefinite"] else "no"] for r in spec]
    baseline = ("; baselines on the held-out frames: " + ", ".join(f"{k} {v} its" for k, v in base.items())) if base else ""
    return "\n\n".join([
        "## 7. Training profile and spectrum",
        f"Training log `{source.get('train_log', '?')}`: {_train_summary(train)}{baseline}.",
        _image(charts.PROFILE, "Training profile"),
        f"Spectrum of M A on the first held-out frame at N = {n_label(spec[0]['n']) if spec else '?'} "
        f"(dense eigendecomposition, null-space eigenvalue removed; HTP from `{source.get('checkpoint', '?')}`). "
        "κ = max|λ| / min|λ|; reduction against no preconditioner:",
        md_table(["M", "κ", "reduction", "λ min", "λ max", "indefinite"], table),
        _image(charts.SPECTRUM, "Spectra of M A"),
    ])


# ----------------------------------------------------------------- 8. fastpath

def fastpath_section(res) -> str:
    """Torch PCG (CUDA Graph on GPU, eager on CPU): time (iterations) and per-iteration costs."""
    rows = res.rows["fastpath"]
    cells = {k: stats.cell(v) for k, v in stats.group(rows, "method", "n").items()}
    methods = stats.ordered(r["method"] for r in rows)
    scales = sorted({r["n"] for r in rows})
    device = rows[0].get("device", "?")
    head = ["Method"] + [n_label(n) for n in scales]
    main = [[m] + [_main_cell(cells.get((m, n)), False) for n in scales] for m in methods]
    per = []
    for m in methods:
        groups = stats.group([r for r in rows if r["method"] == m], "n")
        per.append([m] + [f"{ms(stats.summary(r.get('us_per_iter') for r in g)['median'])} / "
                          f"{ms(stats.summary(r.get('us_per_apply') for r in g)['median'])} / "
                          f"{ms(stats.summary(r.get('inference_ms') for r in g)['median'])}"
                          for (n,), g in sorted(groups.items())])
    where = (f"on {device}" if device != "cpu" else
             "on the CPU: **no CUDA device on this machine, so the fast path ran eagerly (no CUDA Graphs)**")
    notes = sorted({r["note"] for r in rows if r.get("note")})
    return "\n\n".join([
        "## 8. Fast path (torch PCG, CUDA Graphs)",
        f"`petsc_htp.fastpath.run_fastpath` {where}, torch {rows[0].get('torch', '?')}, float32 vectors, "
        "same frames and rtol; setup + solve ms (iterations), mean over the frames (first frame per N a "
        "discarded warm-up)." + (" " + " ".join(notes) if notes else ""),
        md_table(head, main),
        "Median µs per iteration / µs per preconditioner apply / HTP inference ms:",
        md_table(head, per),
        _image(charts.FASTPATH, "Fast path time per frame"),
    ])


# (study name, the study whose rows it reads, section builder)
SECTIONS = (("table", "table", table4_section), ("curves", "curves", curve_section),
            ("scaling", "table", scaling_section), ("stability", "stability", stability_section),
            ("generalization", "generalization", generalization_section), ("size", "size", size_section),
            ("profile", "profile", profile_section), ("fastpath", "fastpath", fastpath_section))


def build(res) -> str:
    """The whole report: the header and the section of every study the run asked for and has rows for."""
    wanted = set(res.meta.get("studies", store.STUDIES))
    parts = [header(res)] + [fn(res) for name, data, fn in SECTIONS if name in wanted and data in res.rows]
    return "\n\n".join(parts) + "\n"
