"""The fast-path benchmark: every method on every frame, JSONL output and the command line."""
from __future__ import annotations

import argparse
import json
import sys

import torch

from ..atomic import write_text
from ..paper.inference import HTP
from .inference_graph import capture_inference
from .preconditioners import METHODS, make_preconditioner
from .solver import GraphPCG
from .timing import device_of


def run_fastpath(frames, methods=METHODS, htp=None, device="auto", check_every=8, rtol=1e-8,
                 maxiter=10000) -> list:
    """Solve every frame with every method; one dict row per (frame, method).

    Solvers (and their graphs) are built once per (N, method) and refreshed for
    later frames. A method that raises gives a row whose reason is "error: ...".
    """
    dev = device_of(device)
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else "cpu"
    cache, graphs, rows = {}, {}, []
    for frame in frames:
        for method in methods:
            key = (frame.n, method)
            row = dict(method=method, n=frame.n, seed=frame.params.get("seed"), setup_ms=None,
                       inference_ms=None, solve_ms=None, total_ms=None, iterations=None, reason=None,
                       us_per_iter=None, us_per_apply=None, device=name, torch=torch.__version__,
                       graphed=None, inference_graphed=None)
            try:
                if key in cache:
                    pc, solver = cache[key]
                    pc.setup(frame.A, frame.coords, frame.rho)
                    solver.set_matrix(frame.A)
                else:
                    pc = make_preconditioner(method, frame.A, htp, frame.coords, frame.rho, dev)
                    pc.setup()
                    solver = GraphPCG(frame.A, pc, dev, check_every, rtol, maxiter)
                    cache[key] = pc, solver
                res = solver.solve(frame.b)
                row.update(setup_ms=res.setup_ms, solve_ms=res.solve_ms, total_ms=res.setup_ms + res.solve_ms,
                           iterations=res.iterations, reason=res.reason, us_per_iter=res.us_per_iter,
                           us_per_apply=res.us_per_apply, graphed=res.graphed)
                if method == "htp":
                    if frame.n not in graphs:
                        graphs[frame.n] = capture_inference(htp, frame.A, frame.coords, frame.rho)
                    infer = graphs[frame.n]
                    infer(frame.A, frame.rho)
                    row.update(inference_ms=infer.inference_ms, inference_graphed=infer.graphed)
            except Exception as exc:  # report and go on with the next method
                cache.pop(key, None)
                row["reason"] = f"error: {type(exc).__name__}: {exc}"
            rows.append(row)
    return rows


def write_jsonl(rows, path):
    """Write rows as JSON lines atomically (temporary file, then rename)."""
    write_text(path, "".join(json.dumps(row) + "\n" for row in rows))


def main(argv=None) -> int:
    """Command line: benchmark the fast path on generated frames and write JSONL rows."""
    from ..scenes.generator import make_frame

    doc = sys.modules[__package__].__doc__   # the package docstring
    ap = argparse.ArgumentParser(prog="python -m petsc_htp.fastpath", description=doc.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1024, 2048], help="problem sizes")
    ap.add_argument("--frames", type=int, default=3, help="frames (seeds 0..F-1) per size")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--device", default="auto", help="auto, cpu or cuda[:i]")
    ap.add_argument("--check-every", type=int, default=8, help="PCG iterations per convergence check")
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--checkpoint", default=None, help="HTP checkpoint (default: the shipped one)")
    ap.add_argument("--out", default="results.jsonl", help="JSONL output file")
    args = ap.parse_args(argv)
    dev = device_of(args.device)
    methods, htp = list(args.methods), None
    if "htp" in methods:
        try:
            htp = HTP.load(args.checkpoint, device=str(dev))
        except Exception as exc:  # no usable checkpoint: benchmark the classical methods only
            print(f"skipping htp: {exc}", file=sys.stderr)
            methods.remove("htp")
    frames = [make_frame(n, seed=s) for n in args.n for s in range(args.frames)]
    rows = run_fastpath(frames, methods, htp, dev, args.check_every, args.rtol)
    write_jsonl(rows, args.out)
    for r in rows:
        print(" ".join(f"{k}={r[k]:.4g}" if isinstance(r[k], float) else f"{k}={r[k]}"
                       for k in ("method", "n", "seed", "iterations", "reason", "setup_ms", "solve_ms")))
    print(f"wrote {len(rows)} rows to {args.out}")
    return 0
