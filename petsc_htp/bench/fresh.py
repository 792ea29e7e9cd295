"""One solve in a fresh process: ``python -m petsc_htp.bench.fresh MATRIX.npz METHOD [--threads T]``.

Loads A (and b) from the ``.npz`` that :func:`save` wrote, imports what the method needs, solves once as the
benchmark does (:func:`petsc_htp.bench.runner.solve_method`) and prints one JSON row on its last line with ``import_ms``
(petsc4py and the package, before any solve), ``baseline_mb`` (resident memory before the solve) and
``peak_rss_mb`` (the peak from then on: Linux lets a process start its peak over): the first call a user's
program pays, and the memory the solve itself takes.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
import scipy.sparse as sp


def save(path, A, b):
    """Write A and b for :func:`main` to read."""
    np.savez(path, data=A.data, indices=A.indices, indptr=A.indptr, shape=A.shape, b=b)


def status_mb(field) -> float:
    """``VmRSS`` or ``VmHWM`` (peak) of this process from /proc, in MiB (the peak since start without /proc)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def reset_peak():
    """Start the peak resident memory (VmHWM) over from the current one (Linux: /proc/self/clear_refs), so that
    the peak after the solve is the solve's and not the imports'."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m petsc_htp.bench.fresh", description=__doc__.splitlines()[0])
    p.add_argument("matrix")
    p.add_argument("method")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--case", default="")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    import petsc4py

    petsc4py.init([])
    from .cases import Problem
    from .methods import resolve_method
    from .runner import solve_method, htp_options, load
    from .studies.foreign import bare_frame

    import_ms = 1e3 * (time.perf_counter() - t0)
    z = np.load(args.matrix)
    A = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(z["shape"]))
    method = resolve_method(args.method)
    loaded = load(method, htp_options(threads=args.threads)) if method.is_petsc else None
    reset_peak()
    baseline = status_mb("VmRSS")
    try:
        row = solve_method(method, method.prefix, Problem(bare_frame(A, z["b"], args.case), case=args.case, attach=False),
                     False)
    finally:
        if loaded is not None:
            loaded.__exit__(None, None, None)
    row.update(import_ms=import_ms, baseline_mb=baseline, peak_rss_mb=status_mb("VmHWM"))
    print(json.dumps(row))
    return 0


def run(path, method, case, threads=1) -> dict:
    """:func:`main` in a new Python process; its row (a failure row when the process failed)."""
    proc = subprocess.run([sys.executable, "-m", "petsc_htp.bench.fresh", str(path), method, "--case", case,
                           "--threads", str(threads)], capture_output=True, text=True)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode or not lines:
        return {"method": method, "case": case, "ok": False, "failure": "EXCEPTION", "reason": "EXCEPTION",
                "error": (proc.stderr.strip().splitlines() or ["no output"])[-1][:300]}
    return json.loads(lines[-1])


if __name__ == "__main__":
    sys.exit(main())
