"""One frame, one method: a PETSc options file under its prefix, or an external solver (pyamg, AMGCL).

PETSc methods are loaded by :class:`petsc_htp.bench.harness.Loaded` (the project's
one loader) and solved by :func:`petsc_htp.bench.harness.solve`, which times
``KSPSetUp`` (plus ``PCSetUpOnBlocks``) and ``KSPSolve`` separately. Every
solve returns one row (a dict); a method that raises, diverges or produces
NaN gives a failure row instead of stopping the run.
"""
from __future__ import annotations

import math
import re
import time

import numpy as np
from petsc4py import PETSc

from .harness import Loaded, common_setting, solve
from ..petscmat import attach, frame_mat, frame_vec, gathered
from . import external

# Options that only print (the bench records the reason itself).
PRINT_ONLY = ("ksp_converged_reason",)
# A converged solve whose true residual misses rtol by more than this factor is a failure.
RESIDUAL_SLACK = 10.0


# ------------------------------------------------------------------ options

def htp_options(checkpoint=None, device=None, threads=0) -> list:
    """``htp_*`` option pairs for every HTP preconditioner (also under ``sub_`` for block Jacobi)."""
    pairs = [("htp_checkpoint", checkpoint and str(checkpoint)), ("htp_device", device),
             ("htp_threads", str(threads) if threads else None)]
    pairs = [(k, v) for k, v in pairs if v]
    return pairs + [("sub_" + k, v) for k, v in pairs]


def load(method, extra=()) -> Loaded:
    """The method's options file under its prefix, plus ``extra``, without the print-only options."""
    loaded = Loaded(method.path, prefix=method.prefix, extra=list(extra) + list(method.extra))
    loaded.__enter__()
    for name in PRINT_ONLY:
        PETSc.Options(method.prefix).delValue(name)
    return loaded


# ------------------------------------------------------------------------- rows

def residuals(A, b, x):
    """``(||b - A x|| / ||b||, the same with the constant (null-space) component removed)``; the second is
    the first when A does not annihilate the constant."""
    r = b - A @ x
    first = float(np.linalg.norm(r) / np.linalg.norm(b))
    if np.abs(A @ np.ones(A.shape[0])).max() > 1e-10 * np.abs(A.diagonal()).max():
        return first, first
    bp, rp = b - b.mean(), r - r.mean()
    return first, float(np.linalg.norm(rp) / np.linalg.norm(bp))


def failure_of(reason, relres, relres_proj, rtol):
    """Failure code of a finished solve, or None when it converged to ``rtol``."""
    if reason.startswith("DIVERGED") or reason == "EXCEPTION":
        return reason
    if not (math.isfinite(relres) and math.isfinite(relres_proj)):
        return "NAN"
    if relres_proj > RESIDUAL_SLACK * rtol:
        return "RESIDUAL"
    return None


def base_row(method, problem) -> dict:
    """The identifying fields of a row."""
    return {"method": method.name, "n": problem.n, "seed": problem.seed, "case": problem.case,
            "rtol": problem.rtol}


def describe(exc) -> str:
    """One line naming an exception: its root cause first, then where PETSc raised it."""
    chain = []
    while exc is not None:
        lines = str(exc).splitlines() or [""]
        where = re.search(r"\] (\w+)\(\)", str(exc))
        chain.append(f"{type(exc).__name__}: {lines[0]}" + (f" in {where.group(1)}()" if where else ""))
        exc = exc.__cause__
    return " ← ".join(reversed(chain))[:300]


def exception_row(method, problem, exc) -> dict:
    """A failure row for a solve that raised."""
    text = describe(exc)
    return {**base_row(method, problem), "ok": False, "failure": "EXCEPTION", "reason": "EXCEPTION",
            "error": text, "setup_ms": None, "solve_ms": None, "total_ms": None, "iterations": None,
            "relres": None, "relres_proj": None}


def finish_row(row, A, b, x, rtol):
    """Add residuals, totals and the failure verdict to ``row``."""
    relres, relres_proj = residuals(A, b, x)
    failure = failure_of(row["reason"], relres, relres_proj, rtol)
    row.update(relres=relres, relres_proj=relres_proj, total_ms=row["setup_ms"] + row["solve_ms"],
               ok=failure is None, failure=failure, rtol=rtol)
    return row


class Recorder:
    """KSP monitor / apply hook recording (ms since :meth:`start`, iteration, ||r|| / ||b||)."""

    def __init__(self, bnorm):
        self.bnorm = bnorm
        self.points = []
        self.t0 = time.perf_counter()

    def start(self):
        """Reset the clock (call right before setup)."""
        self.t0 = time.perf_counter()

    def __call__(self, ksp, its, rnorm):
        self.points.append([1e3 * (time.perf_counter() - self.t0), int(its), float(rnorm) / self.bnorm])


# ------------------------------------------------------------------------ PETSc

def solve_petsc(method, prefix, problem, monitor=False) -> dict:
    """Solve ``problem`` with a fresh KSP under ``prefix``; return its row.

    Setup is ``KSPSetUp`` + ``KSPSetUpOnBlocks`` (inference, AMG setup or
    factorisation); solve is ``KSPSolve``. With ``monitor`` the row gets
    ``curve``: [ms since setup start, iteration, ||r|| / ||b||] per iteration.
    """
    frame = problem.frame
    A = frame_mat(frame)                    # over every rank of the run (one on a plain run)
    if problem.attach:
        attach(A, coords=frame.coords, density=frame.rho)
    b = frame_vec(frame, A)
    rec = Recorder(b.norm())
    res = None
    try:
        rec.start()
        res = solve(A, b, prefix, monitor=rec if monitor else None, rtol=problem.rtol)
        row = {**base_row(method, problem), "setup_ms": res["setup_ms"], "solve_ms": res["solve_ms"],
               "iterations": res["its"], "reason": res["reason"], "ksp": res["ksp"],
               "pc": res["pc"].split("/")[0], "inference_ms": res["htp_setup_ms"],
               "bytes_per_unknown": None if res["htp_bytes"] is None else res["htp_bytes"] / problem.n}
        if monitor:
            row["curve"] = rec.points
        return finish_row(row, frame.A, frame.b, gathered(res["x"]), res["rtol"])
    finally:
        for obj in (A, b) + ((res["x"],) if res else ()):
            obj.destroy()


# ---------------------------------------------------------------- external

def solve_external(method, problem, monitor=False) -> dict:
    """pyamg or AMGCL (:mod:`petsc_htp.bench.external`) from scratch, with the options files' stopping rule.

    ``rtol`` from ``common.opts`` on the unpreconditioned residual, ``ksp_max_it`` iterations at most. Under
    MPI these serial solvers run on rank 0 (one core) and every rank gets the row.
    """
    comm = PETSc.COMM_WORLD
    if comm.getSize() > 1:                  # a serial solver: rank 0 solves on one core, the others wait
        row = _external_row(method, problem, monitor) if comm.getRank() == 0 else None
        return comm.tompi4py().bcast(row, root=0)
    return _external_row(method, problem, monitor)


def _external_row(method, problem, monitor) -> dict:
    frame = problem.frame
    rtol = problem.rtol or common_setting("ksp_rtol", 1e-8)
    res = external.solve(method.name, frame.A, frame.b, rtol, int(common_setting("ksp_max_it", 10000)), monitor)
    row = {**base_row(method, problem), "setup_ms": res["setup_ms"], "solve_ms": res["solve_ms"],
           "iterations": res["iterations"], "reason": res["reason"], "ksp": res["ksp"], "pc": res["pc"],
           "inference_ms": None}
    if monitor:
        row["curve"] = res["curve"]
    return finish_row(row, frame.A, frame.b, res["x"], rtol)


# ----------------------------------------------------------------------- driver

def solve_method(method, prefix, problem, monitor):
    """One solve; any exception becomes a failure row. The row carries the run's peak memory so far."""
    try:
        row = (solve_petsc(method, prefix, problem, monitor) if method.is_petsc
               else solve_external(method, problem, monitor))
    except Exception as exc:  # a failing method is a result, never the end of the run
        row = exception_row(method, problem, exc)
    row["peak_rss_mb"] = peak_rss_mb()
    return row


def peak_rss_mb() -> float:
    """The largest resident set of any rank so far, in MiB (collective)."""
    import resource

    mine = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0        # Linux: KiB
    comm = PETSc.COMM_WORLD
    if comm.getSize() == 1:
        return mine
    from mpi4py import MPI

    return comm.tompi4py().allreduce(mine, op=MPI.MAX)


def run_methods(methods, problems, extra=(), monitor=False, warmup=True, tick=lambda: None,
                repeats=lambda problem: 1) -> list:
    """Solve every problem with every method; one row each, frame by frame.

    Each frame is solved by all methods in turn, so a machine whose speed drifts during the
    run slows every method alike. The options stay loaded for the whole list; with ``warmup``
    the first problem of every N is solved once more by each method beforehand and that solve
    is discarded. A problem is solved ``repeats(problem)`` times by each method in a row and the
    row of the median setup + solve time kept (a millisecond solve varies by its own size from one
    run to the next). ``tick()`` is called after every recorded row.
    """
    loaded, failed = [], {}
    try:
        for method in methods:
            try:
                if method.is_petsc:
                    loaded.append(load(method, extra))
                elif external.missing(method.name):
                    raise RuntimeError(external.missing(method.name))
            except Exception as exc:  # unreadable options file or missing package: every problem fails
                failed[method.name] = exc
        rows, warmed = [], set()
        for problem in problems:
            for method in methods:
                if method.name in failed:
                    rows.append(exception_row(method, problem, failed[method.name]))
                elif warmup and (method.name, problem.n) not in warmed:
                    warmed.add((method.name, problem.n))
                    solve_method(method, method.prefix, problem, False)
                if method.name not in failed:
                    rows.append(_median([solve_method(method, method.prefix, problem, monitor)
                                         for _ in range(repeats(problem))]))
                tick()
    finally:
        for entry in reversed(loaded):
            entry.__exit__(None, None, None)
    return rows


def _median(rows) -> dict:
    """The row of the median total time (the first failed one, if any failed); ``repeats`` says how many ran.
    Under MPI rank 0's choice holds on every rank (each rank's clock differs a little)."""
    bad = [i for i, r in enumerate(rows) if not r.get("ok", True)]
    order = sorted(range(len(rows)), key=lambda i: rows[i].get("total_ms") or 0.0)
    pick = bad[0] if bad else order[(len(rows) - 1) // 2]
    comm = PETSc.COMM_WORLD
    if comm.getSize() > 1:
        pick = comm.tompi4py().bcast(pick, root=0)
    return {**rows[pick], "repeats": len(rows)} if len(rows) > 1 else rows[pick]


def run_method(method, problems, extra=(), monitor=False, warmup=True, tick=lambda: None) -> list:
    """:func:`run_methods` for one method."""
    return run_methods([method], problems, extra, monitor, warmup, tick)
