"""One solve in a fresh process: ``python -m petsc_htp.bench.fresh MATRIX.npz METHOD [--threads T]``.

Loads A (and b) from the ``.npz`` that :func:`save` wrote, imports what the method needs, solves once as the
benchmark does (:func:`petsc_htp.bench.runner._solve`) and prints one JSON row on its last line with ``import_ms``
(petsc4py and the package, before any solve), ``baseline_mb`` (resident memory before the solve) and
``peak_rss_mb`` (after it): the first call a user's program pays, and the memory the solve itself takes.
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


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


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
    from .runner import _solve, htp_options, load
    from .studies.foreign import bare_frame

    import_ms = 1e3 * (time.perf_counter() - t0)
    z = np.load(args.matrix)
    A = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(z["shape"]))
    method = resolve_method(args.method)
    loaded = load(method, htp_options(threads=args.threads)) if method.is_petsc else None
    baseline = _rss_mb()
    try:
        row = _solve(method, method.prefix, Problem(bare_frame(A, z["b"], args.case), case=args.case, attach=False),
                     False)
    finally:
        if loaded is not None:
            loaded.__exit__(None, None, None)
    row.update(import_ms=import_ms, baseline_mb=baseline, peak_rss_mb=_rss_mb())
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
