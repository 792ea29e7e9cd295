"""One method on the DMDA problem of :mod:`petsc_htp.scenes.dmda` under mpiexec, for the ``scale`` study:
``mpiexec -n R python -m petsc_htp.bench.dmdarun --side S --dim D --frames F --method M [--threads T]``.

After a warm-up solve of a small grid (one-time costs out of the timing), frame 0 is a single solve (a fresh KSP,
the whole setup in its time) and frames 1 .. F put the discs (balls) of the next seeds into the same Mat and solve
them with the same KSP (sequence mode). A PETSc method (an options file, :mod:`petsc_htp.bench.methods`) runs on
every rank; pyamg and AMGCL (serial) on one rank only, rebuilding every frame. Rank 0 prints one JSON row per frame
(setup and solve ms, iterations, reason, true relative residual) with the peak resident memory: the largest and the
sum over the ranks, from after the warm-up (``peak_rss_mb``), and above each rank's resident memory then
(``solve_rss_mb``, summed), in MiB.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

CONTRAST = 1000.0
WARMUP_SIDE = {2: 32, 3: 12}


def _petsc(method, da, frames) -> list:
    """The frames' (iterations, reason code, setup ms, solve ms, true relres) on ``da``'s grid with PETSc's KSP under
    the method's options (loaded by the caller): one KSP, new values into its Mat."""
    from ..onesolve import solve_frames
    from ..scenes import dmda

    A = dmda.operator(da, CONTRAST, 0)
    b = dmda.source(A, A.getSize()[0])
    try:
        return solve_frames(A, b, frames, lambda k: dmda.operator(da, CONTRAST, k, mat=A), method.prefix)
    finally:
        A.destroy()
        b.destroy()


def _external(method, da, frames) -> list:
    """The same with a serial solver on one rank, from scratch every frame (its stopping rule that of the options
    files: :func:`.runner.solve_external`)."""
    from ..petscmat import read_csr
    from ..scenes import dmda
    from . import external
    from .harness import common_setting, reason_name

    rtol, maxit = common_setting("ksp_rtol", 1e-8), int(common_setting("ksp_max_it", 10000))
    codes = {reason_name(c): c for c in (2, -3)}
    out = []
    for k in range(frames + 1):
        A = dmda.operator(da, CONTRAST, k)
        rows = read_csr(A)
        A.destroy()
        b = np.full(rows.shape[0], 1.0 / rows.shape[0])
        res = external.solve(method.name, rows, b, rtol, maxit)
        relres = float(np.linalg.norm(b - rows @ res["x"]) / np.linalg.norm(b))
        out.append((res["iterations"], codes.get(res["reason"], -3), res["setup_ms"], res["solve_ms"], relres))
    return out


def measure(method, side, dim, frames, extra) -> tuple:
    """(the frames of :func:`_petsc` or :func:`_external` on a ``side``^``dim`` grid after a warm-up grid, this
    rank's resident MiB before the grid)."""
    from ..scenes import dmda
    from .fresh import reset_peak, status_mb
    from .runner import load

    loaded = load(method, extra) if method.is_petsc else None
    run = _petsc if method.is_petsc else _external
    try:
        for n, count in ((WARMUP_SIDE[dim], 0), (side, frames)):
            if n == side:
                reset_peak()
                base = status_mb("VmRSS")
            da = dmda.grid(n, dim)
            out = run(method, da, count)
            da.destroy()
        return out, base
    finally:
        if loaded is not None:
            loaded.__exit__(None, None, None)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m petsc_htp.bench.dmdarun", description=__doc__.splitlines()[0])
    p.add_argument("--side", type=int, required=True)
    p.add_argument("--dim", type=int, choices=(2, 3), default=2)
    p.add_argument("--frames", type=int, default=0)
    p.add_argument("--method", required=True)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    import petsc4py

    petsc4py.init([])
    from petsc4py import PETSc

    from .fresh import status_mb
    from .harness import common_setting, reason_name
    from .methods import resolve_method
    from .runner import RESIDUAL_SLACK, htp_options

    comm = PETSc.COMM_WORLD.tompi4py()
    method = resolve_method(args.method)
    if not method.is_petsc and comm.size > 1:
        raise SystemExit(f"{method.name} is a serial solver: run it on one rank")
    frames, base = measure(method, args.side, args.dim, args.frames, htp_options(threads=args.threads))
    peak = comm.gather(status_mb("VmHWM"), root=0)
    above = comm.gather(status_mb("VmHWM") - base, root=0)
    if comm.rank:
        return 0
    slack = RESIDUAL_SLACK * common_setting("ksp_rtol", 1e-8)
    for k, (its, code, setup, solve, relres) in enumerate(frames):
        print(json.dumps({"method": method.name, "dim": args.dim, "side": args.side, "n": args.side ** args.dim,
                          "ranks": comm.size, "frame": k, "mode": "sequence" if k else "single",
                          "setup_ms": setup, "solve_ms": solve, "total_ms": setup + solve, "iterations": its,
                          "reason": reason_name(code), "relres": relres, "ok": code > 0 and relres <= slack,
                          "peak_rss_mb": sum(peak), "peak_rank_mb": max(peak), "solve_rss_mb": sum(above)}),
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
