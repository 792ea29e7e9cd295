"""A standalone float32 PCG on torch alone, timed like the paper (no PETSc needed).

The whole inner loop (preconditioner apply, CSR SpMV, SAXPYs, float64 dot
reductions) runs on preallocated device buffers; on CUDA, ``check_every``
unrolled iterations are captured once per (N, method) as one CUDA Graph and
replayed, with one host sync per replay to test convergence. On CPU the same
step function runs eagerly.

    pc = make_preconditioner("jacobi", A)
    res = GraphPCG(A, pc).solve(b)           # res.x, res.iterations, res.reason

``python -m petsc_htp.fastpath --n 1024 --out results.jsonl`` benchmarks every method.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import torch

from .features import build_input
from .inference import HTP, resolve_device
from .ordering import choose_ordering

METHODS = ("none", "jacobi", "bjacobi", "htp")
REASONS = {1: "nan", 2: "indefinite_pc", 3: "indefinite_mat"}


def _device(device) -> torch.device:
    """Resolve 'auto'/'cpu'/'cuda[:i]' (or a torch.device) to a device with an explicit CUDA index."""
    dev = resolve_device(device) if isinstance(device, str) else torch.device(device)
    if dev.type == "cuda" and dev.index is None:
        dev = torch.device("cuda", torch.cuda.current_device())
    return dev


def _constant_null(A) -> bool:
    """True when A 1 = 0 (row sums below 1e-10 max|diag|): constants span a null space."""
    return bool(np.abs(A @ np.ones(A.shape[0])).max() <= 1e-10 * np.abs(A.diagonal()).max())


def _sync(device: torch.device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _timed(fn, device: torch.device):
    """Run ``fn()``; return (its result, milliseconds) from CUDA events on GPU, perf_counter on CPU."""
    if device.type == "cuda":
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        out = fn()
        end.record()
        end.synchronize()
        return out, start.elapsed_time(end)
    t0 = time.perf_counter()
    out = fn()
    return out, 1e3 * (time.perf_counter() - t0)


def _capture(fn, warmup: int = 2):
    """Warm ``fn`` up on a side stream, then capture it; return (CUDAGraph, fn's output)."""
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream):
        for _ in range(warmup):
            fn()
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        out = fn()
    return graph, out


# ------------------------------------------------------------ preconditioners

class Preconditioner:
    """Identity preconditioner and the protocol every method follows.

    ``setup`` computes (or recomputes in place, for a new operator of the same
    N) the device data; ``apply_(r, z)`` writes ``z = M r`` into the float32
    length-N buffer ``z`` with device ops only. ``perm`` (None = identity) is
    the ordering the solver must run in.
    """


    def __init__(self, A, coords=None, density=None, device="auto"):
        self.A, self.coords, self.density = sp.csr_matrix(A), coords, density
        self.n = self.A.shape[0]
        self.device = _device(device)
        self.perm = None
        self.setup_ms = None

    def setup(self, A=None, coords=None, density=None) -> float:
        """(Re)compute for ``A`` (default: the bound operator); return and store the milliseconds."""
        if A is not None:
            if A.shape != (self.n, self.n):
                raise ValueError(f"operator has shape {A.shape}; this preconditioner was built for N={self.n}")
            self.A, self.coords, self.density = sp.csr_matrix(A), coords, density
        t0 = time.perf_counter()
        self._setup()
        _sync(self.device)
        self.setup_ms = 1e3 * (time.perf_counter() - t0)
        return self.setup_ms

    def _setup(self):
        pass

    def apply_(self, r: torch.Tensor, z: torch.Tensor):
        """z = M r in place."""
        z.copy_(r)


class Jacobi(Preconditioner):
    """z = D^-1 r."""

    inv_diag = None

    def _setup(self):
        inv = torch.from_numpy(1.0 / self.A.diagonal()).to(self.device, torch.float32)
        if self.inv_diag is None:
            self.inv_diag = inv
        else:
            self.inv_diag.copy_(inv)

    def apply_(self, r, z):
        torch.mul(r, self.inv_diag, out=z)


class BlockJacobi(Preconditioner):
    """Exact inverses of A's contiguous ``block`` x ``block`` diagonal blocks, one batched GEMM per apply.

    The last block is padded with the identity; one batched float64 Cholesky
    gives the inverses, stored in float32. A singular whole-matrix block
    (N <= block, A 1 = 0) gets the rank-one term max(diag) 11^T / N, so its
    inverse is exact on mean-zero vectors.
    """

    block = 128
    inv = None

    def _setup(self):
        b, n = self.block, self.n
        nb = -(-n // b)
        coo = self.A.tocoo()
        keep = coo.row // b == coo.col // b
        dense = np.zeros((nb, b, b))
        np.add.at(dense, (coo.row[keep] // b, coo.row[keep] % b, coo.col[keep] % b), coo.data[keep])
        pad = np.arange(n, nb * b)
        dense[pad // b, pad % b, pad % b] = 1.0
        blocks = torch.from_numpy(dense).to(self.device)
        if n <= b and _constant_null(self.A):  # one singular block: invert A + max(diag) 11^T / n
            blocks[0, :n, :n] += self.A.diagonal().max() / n
        inv = torch.cholesky_inverse(torch.linalg.cholesky(blocks)).float()
        if self.inv is None:
            self.inv = inv
            self.rp = torch.zeros(nb * b, device=self.device)
            self.zp = torch.zeros_like(self.rp)
        else:
            self.inv.copy_(inv)

    def apply_(self, r, z):
        nb, b = self.inv.shape[:2]
        self.rp[:self.n].copy_(r)
        torch.bmm(self.inv, self.rp.view(nb, b, 1), out=self.zp.view(nb, b, 1))
        z.copy_(self.zp[:self.n])


class HTPPreconditioner(Preconditioner):
    """The learned preconditioner: ``htp.setup`` gives an HTPOperator applied on its own buffers.

    The solver runs in the HTP ordering ``perm``; a new operator's factors are
    copied into the first operator's buffers so a captured graph stays valid.
    """

    op = None

    def __init__(self, A, htp, coords=None, density=None, device="auto"):
        super().__init__(A, coords, density, device)
        if _device(htp.device) != self.device:
            raise ValueError(f"the HTP network lives on {htp.device}, not on {self.device}")
        self.htp = htp

    def _setup(self):
        s = self.htp.setup(self.A, self.coords, self.density)
        if self.op is None:
            self.op = s.op
        else:
            self.op.packed.copy_(s.op.packed)
        self.perm = s.perm

    def apply_(self, r, z):
        self.op.r[:self.n, 0].copy_(r)
        self.op.apply_()
        z.copy_(self.op.y[:self.n, 0])


def make_preconditioner(method, A, htp=None, coords=None, density=None, device="auto") -> Preconditioner:
    """Build (without setting up) preconditioner ``method`` (none, jacobi, bjacobi, htp) for ``A``."""
    classes = {"none": Preconditioner, "jacobi": Jacobi, "bjacobi": BlockJacobi}
    if method == "htp":
        if htp is None:
            raise ValueError("method 'htp' needs a loaded HTP network (htp=None given)")
        return HTPPreconditioner(A, htp, coords, density, device)
    if method not in classes:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    return classes[method](A, coords, density, device)


def apply_microbench(precond: Preconditioner, n_apply: int = 50) -> float:
    """Microseconds per ``precond.apply_`` (one CUDA Graph of ``n_apply`` applies on GPU)."""
    dev = precond.device
    r = torch.randn(precond.n, device=dev)
    z = torch.empty_like(r)

    def run():
        for _ in range(n_apply):
            precond.apply_(r, z)

    if dev.type == "cuda":
        graph, _ = _capture(run, warmup=1)
        _, ms = _timed(graph.replay, dev)
    else:
        precond.apply_(r, z)
        _, ms = _timed(run, dev)
    return 1e3 * ms / n_apply


# ------------------------------------------------------------------- solver

@dataclass
class FastResult:
    """Outcome of :meth:`GraphPCG.solve` (times in ms, per-iteration costs in µs)."""

    x: np.ndarray
    iterations: int
    reason: str          # converged, max_it, indefinite_pc, indefinite_mat, nan
    solve_ms: float
    setup_ms: float
    us_per_iter: float
    us_per_apply: float
    history: list = field(default_factory=list)
    graphed: bool = False

    @property
    def converged(self) -> bool:
        """True when the tolerance was reached."""
        return self.reason == "converged"


class GraphPCG:
    """PCG from x0 = 0 to ||r_k|| <= rtol ||r_0||, float32 vectors and float64 scalars, all on device.

    When A 1 = 0 (Neumann operators) the constants are projected out of b, of
    every residual and of every preconditioned residual, as PETSc does for a
    Mat with a constant null space; float32 rounding would otherwise feed the
    null space and stall the iteration.

    Parameters
    ----------
    A : scipy sparse (N, N)
    precond : Preconditioner
        Set up here if it was not yet; the solver runs in its ordering.
    device : str or torch.device, optional
        Must be the preconditioner's device (the default).
    check_every : int
        Unrolled iterations per convergence check (one host sync each); the
        iteration count stays exact, later steps are frozen on device.
    use_graph : bool, optional
        Replay the ``check_every`` steps as one CUDA Graph (default: on CUDA).
    """

    def __init__(self, A, precond, device=None, check_every=8, rtol=1e-8, maxiter=10000, use_graph=None):
        self.pc = precond
        self.device = dev = precond.device if device is None else _device(device)
        if dev != precond.device:
            raise ValueError(f"solver device {dev} differs from the preconditioner's {precond.device}")
        if check_every < 1 or maxiter < 0 or not rtol > 0:
            raise ValueError("need check_every >= 1, maxiter >= 0 and rtol > 0")
        self.k, self.rtol, self.maxiter = int(check_every), float(rtol), int(maxiter)
        self.use_graph = dev.type == "cuda" if use_graph is None else bool(use_graph)
        if self.use_graph and dev.type != "cuda":
            raise ValueError("CUDA Graphs need a CUDA device")
        if precond.setup_ms is None:
            precond.setup()
        n = self.n = precond.n
        self.x, self.r, self.z, self.p, self.q, self.b = torch.zeros(6, n, device=dev).unbind()
        self.w = torch.zeros(n, dtype=torch.float64, device=dev)
        self.state = torch.zeros(11, dtype=torch.float64, device=dev)
        (self.it, self.done, self.flag, self.rr, self.rr0, self.thresh2,
         self.rz, self.rz_new, self.pAp, self.cap, self.mu) = self.state.unbind()
        self.cap.fill_(self.maxiter)
        self.coef = torch.zeros(4, device=dev)   # float32 alpha, beta, gate, mean
        self.graph = self.A = self.null = None
        self.us_per_apply = None
        self.set_matrix(A)

    def set_matrix(self, A):
        """Load an operator of the same N; with an unchanged pattern only the values are copied."""
        if A.shape != (self.n, self.n):
            raise ValueError(f"operator has shape {A.shape}, expected ({self.n}, {self.n})")
        self.perm = self.pc.perm
        A = sp.csr_matrix(A, dtype=np.float64)
        if self.perm is not None:
            A = A[self.perm][:, self.perm]
        A.sum_duplicates()
        null = _constant_null(A)
        if null != self.null:
            self.graph = None
        self.null = null
        vals = torch.from_numpy(A.data.astype(np.float32))
        if (self.A is not None and np.array_equal(A.indptr, self.pattern[0])
                and np.array_equal(A.indices, self.pattern[1])):
            self.vals.copy_(vals)
            return
        self.pattern = (A.indptr.copy(), A.indices.copy())
        dev = self.device
        self.vals = vals.to(dev)
        with warnings.catch_warnings():   # "sparse CSR support is in beta"
            warnings.simplefilter("ignore", UserWarning)
            self.A = torch.sparse_csr_tensor(torch.from_numpy(A.indptr.astype(np.int64)).to(dev),
                                             torch.from_numpy(A.indices.astype(np.int64)).to(dev),
                                             self.vals, size=(self.n, self.n), check_invariants=False)
        self.graph = None

    def _project(self, v):
        """Remove the mean of ``v`` in place when A has the constant null space."""
        if self.null:
            torch.sum(v, 0, dtype=torch.float64, out=self.mu)
            self.coef[3].copy_(self.mu / self.n)
            v.sub_(self.coef[3])

    def _dot(self, a, b, out):
        torch.mul(a, b, out=self.w)
        torch.sum(self.w, 0, out=out)

    def _start(self):
        """x = 0, r = b, z = M r, p = z and the scalars, on device."""
        self.x.zero_()
        self.r.copy_(self.b)
        self._project(self.r)
        self._dot(self.r, self.r, self.rr)
        self.rr0.copy_(self.rr)
        self.thresh2.copy_(self.rr * self.rtol ** 2)
        self.done.copy_(self.rr <= self.thresh2)
        self.flag.zero_()
        self.it.zero_()
        self.pc.apply_(self.r, self.z)
        self._project(self.z)
        self._dot(self.r, self.z, self.rz)
        self.p.copy_(self.z)

    def _step(self):
        """One PCG iteration; a no-op once converged, broken down or at maxiter."""
        alpha, beta, gate = self.coef[:3].unbind()
        self.p.nan_to_num_(0.0, 0.0, 0.0)   # a broken-down p must not reach x as 0 * NaN
        torch.mv(self.A, self.p, out=self.q)
        self._dot(self.p, self.q, self.pAp)
        active = (self.done == 0) & (self.flag == 0) & (self.it < self.cap)
        nan = ~(torch.isfinite(self.rz) & torch.isfinite(self.pAp))
        code = torch.where(nan, 1.0, torch.where(self.rz <= 0, 2.0, torch.where(self.pAp <= 0, 3.0, 0.0)))
        self.flag.copy_(torch.where(active, code, self.flag))
        active &= code == 0
        alpha.copy_(torch.where(active, self.rz / self.pAp, 0.0))
        self.x.addcmul_(self.p, alpha)
        self.r.addcmul_(self.q, alpha, value=-1)
        self._project(self.r)
        self._dot(self.r, self.r, self.rr)
        self.it.add_(active)
        converged = active & (self.rr <= self.thresh2)
        self.done.add_(converged)
        active &= ~converged
        self.pc.apply_(self.r, self.z)
        self._project(self.z)
        self._dot(self.r, self.z, self.rz_new)
        beta.copy_(torch.where(active, self.rz_new / self.rz, 1.0))
        gate.copy_(active)
        self.p.mul_(beta).addcmul_(self.z, gate)
        self.rz.copy_(torch.where(active, self.rz_new, self.rz))

    def _block(self):
        for _ in range(self.k):
            self._step()

    def solve(self, b) -> FastResult:
        """Solve A x = b (float64 in and out, the caller's ordering).

        The first solve also times the preconditioner apply (``us_per_apply``)
        and, with ``use_graph``, captures the graph; neither is in ``solve_ms``.
        """
        b = np.asarray(b, dtype=np.float64)
        if b.shape != (self.n,):
            raise ValueError(f"right-hand side has shape {b.shape}, expected ({self.n},)")
        perm = self.pc.perm
        if (perm is None) != (self.perm is None) or (perm is not None and not np.array_equal(perm, self.perm)):
            raise ValueError("the preconditioner's ordering changed; call set_matrix with the new operator")
        if self.us_per_apply is None:
            self.us_per_apply = apply_microbench(self.pc)
        if self.use_graph and self.graph is None:
            self.graph, _ = _capture(self._block, warmup=1)
        self.b.copy_(torch.from_numpy((b if perm is None else b[perm]).astype(np.float32)))
        checks = []

        def run():
            self._start()
            while True:
                if self.graph is not None:
                    self.graph.replay()
                else:
                    self._block()
                checks.append(self.state[:5].tolist())
                it, done, flag = checks[-1][:3]
                if done or flag or it >= self.maxiter:
                    return

        _, ms = _timed(run, self.device)
        it, done, flag = (int(v) for v in checks[-1][:3])
        reason = REASONS[flag] if flag else ("converged" if done else "max_it")
        xp = self.x.double().cpu().numpy()
        x = np.empty(self.n)
        if perm is None:
            x[:] = xp
        else:
            x[perm] = xp
        history = [math.sqrt(checks[0][4])] + [math.sqrt(c[3]) for c in checks]
        return FastResult(x, it, reason, ms, self.pc.setup_ms, 1e3 * ms / max(it, 1), self.us_per_apply,
                          history, self.graph is not None)


# ---------------------------------------------------------------- inference

class InferenceGraph:
    """The HTP network forward for one N on static inputs: a CUDA Graph on GPU, eager otherwise.

    ``scale`` is kept as a device tensor so a replay reads each frame's value.
    If capture fails, the forward stays eager and ``error`` says why.
    """

    def __init__(self, htp, A, coords=None, density=None):
        self.htp, self.device = htp, htp.device
        self.part = htp.net.cfg.partition(A.shape[0])
        self.inp = self._features(A, coords, density)
        self.graph, self.error = None, None
        self.inference_ms = None
        with torch.no_grad():
            self.out = htp.net(self.inp, self.part)
            if self.device.type == "cuda":
                try:
                    self.graph, self.out = _capture(lambda: htp.net(self.inp, self.part))
                except Exception as exc:  # any op the capture rejects: stay eager
                    self.error = f"{type(exc).__name__}: {exc}"

    @property
    def graphed(self) -> bool:
        """True when the forward replays as a CUDA Graph."""
        return self.graph is not None

    def _features(self, A, coords, density):
        A = sp.csr_matrix(A)
        p, _ = choose_ordering(A, coords, "auto")
        self.perm = p
        inp = build_input(A[p][:, p], self.part, None if coords is None else np.asarray(coords)[p],
                          None if density is None else np.asarray(density)[p])
        inp.scale = torch.tensor(inp.scale, dtype=torch.float32)
        return inp.to(self.device)

    @torch.no_grad()
    def __call__(self, A, coords=None, density=None) -> torch.Tensor:
        """Refresh the inputs from ``A`` (same N and pattern); return the packed factors.

        The forward's milliseconds (features excluded) go to ``inference_ms``.
        """
        new = self._features(A, coords, density)
        for name, value in vars(new).items():
            old = getattr(self.inp, name)
            if value.layout == torch.sparse_coo:
                if value._nnz() != old._nnz():
                    raise ValueError("the operator's sparsity pattern differs from the captured one")
                old._indices().copy_(value._indices())
                old._values().copy_(value._values())
            else:
                old.copy_(value)
        if self.graph is not None:
            _, self.inference_ms = _timed(self.graph.replay, self.device)
        else:
            self.out, self.inference_ms = _timed(lambda: self.htp.net(self.inp, self.part), self.device)
        return self.out


def capture_inference(htp, A, coords=None, density=None) -> InferenceGraph:
    """Capture the network forward for ``A``'s N (CUDA Graph on GPU, eager on CPU)."""
    return InferenceGraph(htp, A, coords, density)


# ---------------------------------------------------------------- benchmark

def run_fastpath(frames, methods=METHODS, htp=None, device="auto", check_every=8, rtol=1e-8,
                 maxiter=10000) -> list:
    """Solve every frame with every method; one dict row per (frame, method).

    Solvers (and their graphs) are built once per (N, method) and refreshed for
    later frames. A method that raises gives a row whose reason is "error: ...".
    """
    dev = _device(device)
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
                    infer(frame.A, frame.coords, frame.rho)
                    row.update(inference_ms=infer.inference_ms, inference_graphed=infer.graphed)
            except Exception as exc:  # report and go on with the next method
                cache.pop(key, None)
                row["reason"] = f"error: {type(exc).__name__}: {exc}"
            rows.append(row)
    return rows


def write_jsonl(rows, path):
    """Write rows as JSON lines atomically (temporary file, then rename)."""
    path = os.path.abspath(path)
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), prefix=os.path.basename(path), suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.writelines(json.dumps(row) + "\n" for row in rows)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def main(argv=None) -> int:
    """Command line: benchmark the fast path on generated frames and write JSONL rows."""
    from .scenes import make_frame

    ap = argparse.ArgumentParser(prog="python -m petsc_htp.fastpath", description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1024, 2048], help="problem sizes")
    ap.add_argument("--frames", type=int, default=3, help="frames (seeds 0..F-1) per size")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--device", default="auto", help="auto, cpu or cuda[:i]")
    ap.add_argument("--check-every", type=int, default=8, help="PCG iterations per convergence check")
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--checkpoint", default=None, help="HTP checkpoint (default: the shipped one)")
    ap.add_argument("--out", default="results.jsonl", help="JSONL output file")
    args = ap.parse_args(argv)
    dev = _device(args.device)
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


if __name__ == "__main__":
    sys.exit(main())
