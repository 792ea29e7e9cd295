"""The on-device float32 PCG (:class:`GraphPCG`) and its result (:class:`FastResult`)."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import torch

from .preconditioners import constant_null, apply_microbench
from .timing import capture, device_of, timed

REASONS = {1: "nan", 2: "indefinite_pc", 3: "indefinite_mat"}


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
        self.device = dev = precond.device if device is None else device_of(device)
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
        null = constant_null(A)
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
            self.graph, _ = capture(self._block, warmup=1)
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

        _, ms = timed(run, self.device)
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
