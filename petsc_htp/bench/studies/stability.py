"""Stability map: every method on stress cases beyond the table's setting (no warm-up).

A frame fails on a KSP divergence, an exception, a NaN, a true residual above
10 × rtol, or (``BUDGET``) when its setup + solve exceeds the frame budget. The
budget is checked after the solve, which runs to its end: the iterations stay
comparable and the timing is not perturbed by a per-iteration callback, at the
price of slow methods running long on the large cases.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ...scenes.generator import Frame, make_frame
from ..aggregate import first_failure, group, ordered, summary
from ..cases import Problem, held_out_frames, held_out_seeds
from ..markdown import image, its, md_table, n_label, sci
from ..plotting import figure, heatmap, save
from .base import DIM, Size, Study, solve_all

CHART = "stability.png"
STRESS = (
    ("reference", "full distribution, random rhs (the table's setting)"),
    ("contrast 1e2", "heavy density fixed at 100 (top of the training range)"),
    ("contrast 1e3", "heavy density fixed at 1000 (10x past training)"),
    ("contrast 1e4", "heavy density fixed at 10000 (100x past training)"),
    ("contrast 1e6", "heavy density fixed at 1e6"),
    ("contrast 1e8", "heavy density fixed at 1e8"),
    ("closed only", "only closed barriers (sealed sub-domains)"),
    ("regions", "closed-only frames with every heavy/light coupling cut: disconnected regions, one constant "
                "null vector each, rhs mean-zero per region"),
    ("large N", "N larger than any training scale"),
    ("huge N", "N far past training"),
    ("odd N", "N not a power of two (ragged last grid row, partial last leaf)"),
    ("rtol 1e-10", "tolerance 1e-10"),
    ("rtol 1e-12", "tolerance 1e-12 (near double-precision limit)"),
    ("rtol 1e-14", "tolerance 1e-14 (at the double-precision limit)"),
    ("natural order", "row-major ordering, no coordinates or density attached"),
    ("permuted bare", "random symmetric row permutation, no coordinates or density attached"),
    ("buoyancy rhs", "rhs -d(rho)/dy, supported on density interfaces only"),
    ("inconsistent rhs", "b + 0.1 rms(b): not mean-zero, outside the range of the singular A"),
    ("simulation", "frames of the two-phase flow run (density ratio 1000, x0 = 0, fresh KSP)"),
)


def natural_order(frame) -> Frame:
    """The frame permuted from Morton to row-major order (the grid's natural numbering)."""
    return _reordered(frame, np.argsort(frame.perm, kind="stable"), "natural")


def permuted(frame, seed=0) -> Frame:
    """The frame under a random symmetric permutation (seeded)."""
    return _reordered(frame, np.random.default_rng(seed).permutation(frame.n), "random")


def _reordered(frame, order, name) -> Frame:
    """The frame with its rows and columns taken in ``order``."""
    A = frame.A[order][:, order].tocsr()
    A.sort_indices()
    return dataclasses.replace(frame, A=A, b=frame.b[order], rho=frame.rho[order],
                               coords=frame.coords[order], perm=frame.perm[order],
                               params={**frame.params, "ordering": name})


def inconsistent(frame, offset=0.1) -> Frame:
    """The frame with ``offset * rms(b)`` added to every entry of b: b leaves the range of A."""
    shift = offset * float(np.sqrt(np.mean(frame.b ** 2)))
    return dataclasses.replace(frame, b=frame.b + shift, params={**frame.params, "rhs_offset": shift})


def sealed(frame) -> Frame:
    """The frame with every coupling between heavy and light cells removed, b made mean-zero per region.

    Heavy cells are those above the geometric mean of 1 and ``rho_heavy``; the
    diagonal is rebuilt so every row still sums to zero.
    """
    heavy = frame.rho > np.sqrt(frame.params["rho_heavy"])
    C = frame.A.tocoo()
    keep = (C.row != C.col) & (heavy[C.row] == heavy[C.col])
    W = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=C.shape)
    A = (W - sp.diags(np.asarray(W.sum(axis=1)).ravel())).tocsr()
    A.sort_indices()
    count, regions = connected_components(A, directed=False)
    b = frame.b - (np.bincount(regions, frame.b) / np.bincount(regions))[regions]
    return dataclasses.replace(frame, A=A, b=b, params={**frame.params, "regions": int(count)})


def over_budget(rows, budget_ms) -> list:
    """``rows`` with every converged row slower than ``budget_ms`` (setup + solve) marked ``BUDGET``."""
    for row in rows:
        if row.get("ok") and row["total_ms"] > budget_ms:
            row.update(ok=False, failure="BUDGET", budget_ms=budget_ms)
    return rows


def _contrast(n, count, value, dim=2):
    """Frames whose heavy density is fixed at ``value`` (range ``[0.99 value, value]``)."""
    return [make_frame(n, s, "full", contrast=(0.99 * value, value), dim=dim) for s in held_out_seeds(count)]


def problems(n, frames, large_n, odd_n, huge_n, dim=2) -> list:
    """Every stress case of :data:`STRESS` in ``dim`` dimensions, ``frames`` frames each (grouped by case)."""
    from .simulation import flow_frames

    def held(size, distribution="full"):
        return held_out_frames(size, frames, distribution, dim)

    base = held(n)
    cases = {
        "reference": [Problem(f) for f in base],
        "contrast 1e2": [Problem(f) for f in _contrast(n, frames, 1e2, dim)],
        "contrast 1e3": [Problem(f) for f in _contrast(n, frames, 1e3, dim)],
        "contrast 1e4": [Problem(f) for f in _contrast(n, frames, 1e4, dim)],
        "contrast 1e6": [Problem(f) for f in _contrast(n, frames, 1e6, dim)],
        "contrast 1e8": [Problem(f) for f in _contrast(n, frames, 1e8, dim)],
        "closed only": [Problem(f) for f in held(n, "closed_only")],
        "regions": [Problem(sealed(f)) for f in held(n, "closed_only")],
        "large N": [Problem(f) for f in held(large_n)],
        "huge N": [Problem(f) for f in held(huge_n)],
        "odd N": [Problem(f) for f in held(odd_n)],
        "rtol 1e-10": [Problem(f, rtol=1e-10) for f in base],
        "rtol 1e-12": [Problem(f, rtol=1e-12) for f in base],
        "rtol 1e-14": [Problem(f, rtol=1e-14) for f in base],
        "natural order": [Problem(natural_order(f), attach=False) for f in base],
        "permuted bare": [Problem(permuted(f, k), attach=False) for k, f in enumerate(base)],
        "buoyancy rhs": [Problem(make_frame(n, s, "full", rhs="buoyancy", dim=dim)) for s in held_out_seeds(frames)],
        "inconsistent rhs": [Problem(inconsistent(f)) for f in base],
        "simulation": [Problem(f) for f in flow_frames(n, frames, dim=dim)],
    }
    out = []
    for name, _ in STRESS:
        for p in cases[name]:
            p.case = name
            out.append(p)
    return out


def run(methods, settings, extra, tick) -> list:
    """Every method on every stress case (no warm-up: iterations and failures matter here), budget applied."""
    s = settings
    cases = problems(s["stress_n"], s["stress_frames"], s["large_n"], s["odd_n"], s["huge_n"], s["dim"])
    return over_budget(solve_all(methods, cases, extra, tick, "stability", warmup=False), s["frame_budget_ms"])


def _hard(rows):
    """First failure other than the budget (short label), or None."""
    return first_failure([r for r in rows if r.get("failure") != "BUDGET"])


def _cell(rows):
    hard = _hard(rows)
    median = its(summary(r["iterations"] for r in rows)["median"])
    if hard:
        return f"✗ {hard}"
    return f"✗ budget ({median})" if first_failure(rows) else median


def boundary(rows, methods, cases) -> dict:
    """The first case (in ``cases`` order) where each method has a failing frame (None: no failure)."""
    groups = group(rows, "case", "method")
    return {m: next((c for c in cases if first_failure(groups.get((c, m), []))), None) for m in methods}


def _inconsistent_note(rows):
    """What the converged iterations of the inconsistent-rhs case mean."""
    true = summary(r.get("relres") for r in rows if r["case"] == "inconsistent rhs" and r.get("ok"))
    return ("Inconsistent rhs: methods converge on the residual with the constant (null-space) part "
            f"removed; the true ||b - A x|| / ||b|| stays at {sci(true['median'])} (median), the constant "
            "part of b that no x can match.") if true["count"] else ""


def chart(res, out) -> str:
    """Methods × stress cases: colour = log10 median iterations, red = failure with its code.

    A cell over the frame budget only keeps its colour and gets a ``*``; each
    method's boundary (its first failing case) is framed in black.
    """
    from matplotlib.patches import Rectangle

    rows = res.rows["stability"]
    methods = res.methods("stability")
    cases = ordered((r["case"] for r in rows), dict(STRESS))
    groups = group(rows, "case", "method")
    values = np.full((len(cases), len(methods)), np.nan)
    labels = np.full(values.shape, "", dtype=object)
    for (i, case), (j, m) in ((a, b) for a in enumerate(cases) for b in enumerate(methods)):
        g = groups.get((case, m), [])
        hard = _hard(g)
        if g and not hard:
            values[i, j] = summary(r["iterations"] for r in g)["median"]
            labels[i, j] = f"{values[i, j]:.0f}" + ("*" if first_failure(g) else "")
        else:
            labels[i, j] = hard or ""
    fig, ax = figure(1.5 + 1.1 * len(methods), 1.2 + 0.42 * len(cases))
    im = heatmap(ax[0, 0], values, labels, cases, methods)
    for j, m in enumerate(methods):
        case = boundary(rows, [m], cases)[m]
        if case is not None:
            ax[0, 0].add_patch(Rectangle((j - 0.5, cases.index(case) - 0.5), 1, 1, fill=False, lw=2.5, ec="black"))
    fig.colorbar(im, ax=ax[0, 0], label="log10 iterations")
    ax[0, 0].set_title("Stability map (red: failure, *: over the frame budget, box: first failing case)",
                       fontsize=9)
    return save(fig, out, CHART)


class Stability(Study):
    """Methods × stress cases."""

    name = "stability"
    help = ("methods x stress cases (contrast up to 1e8, closed barriers, disconnected regions, large/huge/odd N, "
            "tight rtol, natural and random orderings, buoyancy and inconsistent rhs, simulation frames) "
            "within a frame budget")
    default = True
    sizes = (Size("stress_n", 4096, 256, "N of the stress cases"),
             Size("stress_frames", 3, 1, "frames per stress case"),
             Size("large_n", 65536, 2048, "the 'large N' stress case"),
             Size("odd_n", 3000, 300, "the 'odd N' stress case"),
             Size("huge_n", 262144, 4096, "the 'huge N' stress case"),
             Size("frame_budget_ms", 41.7, 41.7, "setup + solve ms a stress frame may take (24 fps)"), DIM)
    readme_links = ((CHART, "stability map"),)

    def meta(self, settings):
        return {"stress": {"n": settings["stress_n"], "frames": settings["stress_frames"],
                           "large_n": settings["large_n"], "odd_n": settings["odd_n"],
                           "huge_n": settings["huge_n"], "budget_ms": settings["frame_budget_ms"],
                           "dim": settings["dim"]}}

    def expected_solves(self, ctx):
        return len(ctx.methods) * len(STRESS) * ctx.settings["stress_frames"]

    def measure(self, ctx, tick):
        return run(ctx.methods, ctx.settings, ctx.extra, tick)

    def section(self, res):
        rows = res.rows["stability"]
        groups = group(rows, "case", "method")
        methods = res.methods("stability")
        meta = res.meta.get("stress", {})
        cases = ordered((r["case"] for r in rows), dict(STRESS))
        table = [[case] + [_cell(groups[(case, m)]) if (case, m) in groups else "—" for m in methods]
                 for case in cases]
        edge = boundary(rows, methods, cases)
        fails = [[r["method"], r["case"], n_label(r["n"]), str(r.get("seed")), r.get("failure") or "",
                  its(r.get("iterations")), sci(r.get("relres_proj")), (r.get("error") or "")[:120]]
                 for r in rows if not r.get("ok")]
        parts = [
            "## 4. Stability map",
            f"Median iterations over {meta.get('frames', '?')} frame(s) per case at N = "
            f"{n_label(meta.get('n', 0))} (large N = {n_label(meta.get('large_n', 0))}, huge N = "
            f"{n_label(meta.get('huge_n', 0))}, odd N = {n_label(meta.get('odd_n', 0))}); ✗ marks a case where at "
            "least one frame failed, with the first failure: max it (DIVERGED_ITS), breakdown, indef. PC, NaN/Inf, "
            "exception, true res. (converged but ||b - A x|| above 10 × rtol after removing the null-space part), "
            f"or budget (converged, but setup + solve above the {meta.get('budget_ms', '?')} ms frame budget; "
            "checked after the solve, median iterations in parentheses). No warm-up.",
            md_table(["Case"] + methods, table),
            "Boundary (first failing case of each method, in the order above): " + "; ".join(
                f"{m}: {edge[m] or 'none'}" for m in methods) + ".",
            _inconsistent_note(rows),
            "Cases: " + "; ".join(f"**{k}**: {v}" for k, v in STRESS) + ".",
            image(CHART, "Stability map"),
        ]
        if fails:
            parts += ["Failures:", md_table(["Method", "Case", "N", "seed", "failure", "its", "true res.", "error"],
                                            fails, left=2)]
        return "\n\n".join(p for p in parts if p)

    def charts(self, res, out):
        return [chart(res, out)]


STUDY = Stability()
