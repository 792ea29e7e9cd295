"""Aggregates of result rows, shared by every report section, chart and the README block.

Rows are grouped by any of their fields (:func:`group`); a group of solves is
summarised by :func:`cell` (time and iteration statistics over its converged
rows, failures counted and named), every group at once by :func:`cells`.
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

FPS_BUDGETS = ((24, 1e3 / 24), (60, 1e3 / 60))   # (fps, ms per frame)
TOLERANCES = (1e-3, 1e-6, 1e-8)
SHORT_FAILURES = {"DIVERGED_ITS": "max it", "DIVERGED_MAX_IT": "max it", "DIVERGED_BREAKDOWN": "breakdown",
                  "DIVERGED_BREAKDOWN_BICG": "breakdown", "DIVERGED_INDEFINITE_PC": "indef. PC",
                  "DIVERGED_INDEFINITE_MAT": "indef. A", "DIVERGED_NANORINF": "NaN/Inf", "DIVERGED_DTOL": "diverged",
                  "NAN": "NaN", "EXCEPTION": "exception", "RESIDUAL": "true res."}
TIMED = ("total_ms", "setup_ms", "solve_ms", "iterations", "inference_ms", "bytes_per_unknown")


def group(rows, *keys) -> dict:
    """Rows bucketed by the tuple of ``keys`` (insertion ordered)."""
    out = defaultdict(list)
    for row in rows:
        out[tuple(row.get(k) for k in keys)].append(row)
    return dict(out)


def ordered(values, preferred=()) -> list:
    """Distinct values, those in ``preferred`` first in that order, then the rest as met."""
    seen = list(dict.fromkeys(values))
    return [v for v in preferred if v in seen] + [v for v in seen if v not in preferred]


def summary(values) -> dict:
    """Median, mean, std (population) and count of the finite values (NaN when none)."""
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return {"median": math.nan, "mean": math.nan, "std": math.nan, "count": 0}
    return {"median": float(np.median(arr)), "mean": float(arr.mean()), "std": float(arr.std()),
            "count": int(arr.size)}


def cell(rows) -> dict:
    """Summary of one group of solves: :data:`TIMED` statistics over its converged rows, and its failures."""
    ok = [r for r in rows if r.get("ok")]
    out = {key: summary(r.get(key) for r in ok) for key in TIMED}
    out["frames"] = len(rows)
    out["failed"] = len(rows) - len(ok)
    out["failure"] = first_failure(rows)
    out["relres_max"] = max((r["relres_proj"] for r in ok if r.get("relres_proj") is not None), default=math.nan)
    return out


def cells(rows, *keys) -> dict:
    """:func:`cell` of every group of :func:`group` ``(rows, *keys)``."""
    return {k: cell(v) for k, v in group(rows, *keys).items()}


def value(c, key="total_ms", what="mean") -> float:
    """One statistic of a cell; NaN for a missing cell or one without converged rows."""
    return c[key][what] if c and c[key]["count"] else math.nan


def first_failure(rows):
    """Short label of the first failing row (None when every row converged)."""
    for row in rows:
        if not row.get("ok"):
            return SHORT_FAILURES.get(row.get("failure"), row.get("failure") or "failed")
    return None


def scaling_exponent(ns, ms):
    """Least-squares slope p of log(ms) = a + p log(N); None with fewer than two points."""
    pts = [(n, t) for n, t in zip(ns, ms) if t is not None and math.isfinite(t) and t > 0]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def largest_within(ns, ms, budget_ms):
    """The largest N whose time is within ``budget_ms`` (None if none is)."""
    fits = [n for n, t in zip(ns, ms) if t is not None and math.isfinite(t) and t <= budget_ms]
    return max(fits) if fits else None


def time_to(curve, tol):
    """Milliseconds at which a [ms, iteration, relres] curve first reaches ``tol`` (None if never)."""
    for t, _, rel in curve or ():
        if rel is not None and rel <= tol:
            return float(t)
    return None


def pareto_front(points) -> list:
    """Indices of the points (x, y) not dominated by another (both to be minimised), sorted by x."""
    front = []
    for i, (x, y) in enumerate(points):
        dominated = any((x2 <= x and y2 <= y) and (x2 < x or y2 < y) for j, (x2, y2) in enumerate(points) if j != i)
        if not dominated and math.isfinite(x) and math.isfinite(y):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def condition_number(eigs):
    """max|lambda| / min|lambda| over the given (null space already removed) eigenvalues."""
    mags = np.abs(np.asarray(eigs, dtype=float))
    return float(mags.max() / mags.min()) if mags.size and mags.min() > 0 else math.inf
