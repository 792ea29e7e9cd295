"""One method on the DMDA problem of :mod:`petsc_htp.scenes.dmda` under mpiexec, for the ``scale`` study:
``mpiexec -n R python -m petsc_htp.bench.dmdarun --side S --dim D --frames F --method M [--threads T]
[--checkpoint C] [--device D]`` (``M`` a method's name, or an options file's path: :attr:`.methods.Method.spec`).

After a warm-up solve of a grid no larger (one-time costs out of the timing: 192^2 or 24^3, past the sizes HTPPC
factors whole, so that 2-D takes the V-cycles and 3-D the two-level method as the measured grids do), frame 0 is a
single solve (a fresh KSP, the whole setup in its time) and frames 1 .. F put the discs (balls) of the next seeds
into the same Mat and solve them with the same KSP (sequence mode). A PETSc method (an options file,
:mod:`petsc_htp.bench.methods`) runs on every rank; pyamg and AMGCL (serial) on one rank only, rebuilding every
frame. Rank 0 prints one JSON row per frame as it ends (setup and solve ms between barriers, iterations, reason, true
relative residual, the verdict of :func:`.runner.failure_of`; a frame that raised ends the run with a failure row).
Frame 0's row carries the peak resident memory of its setup and solve, from after the operator and right-hand side
were made (the problem generator's arrays out): the sum over the ranks (``peak_rss_mb``, each process's whole
resident set: imports and the matrix in), the largest rank's (``peak_rank_mb``) and the sum of what each rank's grew
above its resident set before the solve (``solve_rss_mb``), in MiB.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

CONTRAST = 1000.0
WARMUP_SIDE = {2: 192, 3: 24}   # warm-up grids (or the measured one, where smaller)
ABORT_DELAY_S = 0.5     # a failing rank's wait between its row and MPI_Abort: where both ranks raised, the abort of the
# one had ended the job before mpiexec forwarded either row (the scale study's failure row said 'no output', once
# in a full test run)


class _Meter:
    """Each rank's peak resident memory from :meth:`start` (collective :meth:`read`)."""

    def __init__(self, comm):
        self.comm, self.base = comm, 0.0

    def start(self):
        from .fresh import reset_peak, status_mb

        reset_peak()
        self.base = status_mb("VmRSS")

    def read(self) -> dict:
        from .fresh import status_mb

        peak, base = zip(*self.comm.allgather((status_mb("VmHWM"), self.base)))
        return {"peak_rss_mb": sum(peak), "peak_rank_mb": max(peak), "solve_rss_mb": sum(peak) - sum(base)}


def _petsc(method, da, frames, meter, emit):
    """The frames with PETSc's KSP under the method's options (loaded by the caller): one KSP, new values into its
    Mat; ``emit(k, fields)`` after each."""
    from ..onesolve import solve_frames
    from ..scenes import dmda
    from .harness import bjacobi_blocks, reason_name

    A = dmda.operator(da, CONTRAST, 0)
    b = dmda.source(A, A.getSize()[0])

    def each(k, result):
        its, code, setup, solve, relres = result
        emit(k, {"iterations": its, "reason": reason_name(code), "setup_ms": setup, "solve_ms": solve,
                 "relres": relres, **(meter.read() if k == 0 else {})})

    try:
        meter.start()
        with bjacobi_blocks(method.prefix, A.getSize()[0], A.getComm().getSize()):
            solve_frames(A, b, frames, lambda k: dmda.operator(da, CONTRAST, k, mat=A), method.prefix, each)
    finally:
        A.destroy()
        b.destroy()


def _external(method, da, frames, meter, emit):
    """The same with a serial solver on one rank, from scratch every frame, as the benchmark runs it
    (:func:`.runner.solve_method`)."""
    from ..petscmat import read_csr
    from ..scenes import dmda
    from .cases import Problem
    from .runner import solve_method
    from .studies.foreign import bare_frame

    for k in range(frames + 1):
        A = dmda.operator(da, CONTRAST, k)
        rows = read_csr(A)
        A.destroy()
        b = np.full(rows.shape[0], 1.0 / rows.shape[0])
        problem = Problem(bare_frame(rows, b, ""), attach=False)
        if k == 0:
            meter.start()
        row = solve_method(method, method.prefix, problem, False)
        emit(k, {key: row.get(key) for key in ("iterations", "reason", "setup_ms", "solve_ms", "relres", "error")}
             | (meter.read() if k == 0 else {}))


def measure(method, side, dim, frames, extra, emit):
    """:func:`_petsc` or :func:`_external` on a ``side``^``dim`` grid after the warm-up grid's frame 0, whose rows
    go nowhere."""
    from mpi4py import MPI

    from ..scenes import dmda
    from .runner import load

    run = _petsc if method.is_petsc else _external
    loaded = load(method, extra) if method.is_petsc else None
    try:
        for n, count, out in ((min(WARMUP_SIDE[dim], side), 0, lambda k, fields: None), (side, frames, emit)):
            da = dmda.grid(n, dim)
            try:
                run(method, da, count, _Meter(MPI.COMM_WORLD), out)
            finally:
                da.destroy()
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
    p.add_argument("--checkpoint")
    p.add_argument("--device")
    args = p.parse_args(argv)
    import petsc4py

    petsc4py.init([])
    from mpi4py import MPI

    from .harness import common_setting
    from .methods import resolve_method
    from .runner import describe, failure_of, htp_options

    comm = MPI.COMM_WORLD
    method = resolve_method(args.method)
    if not method.is_petsc and comm.size > 1:
        raise SystemExit(f"{method.name} is a serial solver: run it on one rank")
    rtol, done = common_setting("ksp_rtol", 1e-8), []
    base = {"method": method.name, "dim": args.dim, "side": args.side, "n": args.side ** args.dim, "ranks": comm.size}

    def emit(k, fields):
        failure = failure_of(fields["reason"], fields["relres"], fields["relres"], rtol)
        timed = fields["setup_ms"] is not None and fields["solve_ms"] is not None
        row = {**base, "frame": k, "mode": "sequence" if k else "single", **fields, "ok": failure is None,
               "failure": failure, "total_ms": fields["setup_ms"] + fields["solve_ms"] if timed else None}
        done.append(k)
        if comm.rank == 0:
            print(json.dumps(row), flush=True)

    try:
        measure(method, args.side, args.dim, args.frames, htp_options(args.checkpoint, args.device, args.threads),
                emit)
    except Exception as exc:  # a failing frame is a result: its row (from the rank that raised), then the end
        print(json.dumps({**base, "frame": len(done), "mode": "sequence" if done else "single", "ok": False,
                          "failure": "EXCEPTION", "reason": "EXCEPTION", "error": describe(exc)}), flush=True)
        if comm.size > 1:                   # the others may wait in a collective
            time.sleep(ABORT_DELAY_S)       # the row forwarded by mpiexec before the abort ends the job
            comm.Abort(1)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
