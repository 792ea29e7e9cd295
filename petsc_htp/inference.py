"""From a sparse operator to a ready-to-apply HTP preconditioner (no PETSc needed).

    htp = HTP.load()                         # the shipped checkpoint
    pre = htp.setup(A, coords=xy)            # ordering, partition, network, factors
    y = pre.apply(r)                         # y = M r, float64 in and out
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch

from . import checkpoint
from .apply import HTPOperator
from .features import build_input
from .model import HTPNet
from .ordering import choose_ordering


def resolve_device(device: str = "auto") -> torch.device:
    """'auto' -> cuda when available, else cpu; unknown names raise ValueError."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device not in ("cpu", "cuda") and not device.startswith("cuda:"):
        raise ValueError(f"unknown device {device!r}; use cpu, cuda or auto")
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} requested but CUDA is not available")
    return torch.device(device)


@dataclass
class Setup:
    """An HTP preconditioner bound to one operator."""

    op: HTPOperator
    perm: np.ndarray
    ordering: str
    setup_ms: float
    shift: float
    guard_shift: float = 0.0

    @property
    def n(self) -> int:
        """Problem size N."""
        return self.op.part.n

    def apply(self, r: np.ndarray) -> np.ndarray:
        """Return M r in the caller's ordering (float64)."""
        y = np.empty(self.n)
        y[self.perm] = self.op.apply(np.asarray(r, dtype=np.float64)[self.perm])
        return y

    def factors_finite(self) -> bool:
        """True when every packed factor is finite."""
        return bool(torch.isfinite(self.op.packed).all())

    def min_scaled_eigenvalue(self, diag: np.ndarray, seed: int = 0) -> float:
        """Smallest eigenvalue of D^1/2 M D^1/2 to 1 % by Lanczos on M's device (20 to 100 applies)."""
        op, n = self.op, self.n
        sd = torch.as_tensor(np.sqrt(diag), dtype=op.r.dtype, device=op.r.device)

        def scaled(v):
            op.r[:n, 0] = sd * v
            return sd * op.apply_()[:n, 0]

        return smallest_ritz_value(scaled, n, seed=seed, dtype=op.r.dtype, device=op.r.device)

    def min_rayleigh(self, probes: int = 8, seed: int = 0) -> float:
        """Smallest Rayleigh quotient r^T M r / r^T r over random probes (< 0 proves M indefinite)."""
        rng = np.random.default_rng(seed)
        vals = []
        for _ in range(probes):
            r = rng.standard_normal(self.n)
            vals.append(float(r @ self.apply(r) / (r @ r)))
        return min(vals)


def smallest_ritz_value(matvec, n: int, max_steps: int = 100, rtol: float = 1e-2, seed: int = 0,
                        dtype=torch.float64, device="cpu") -> float:
    """Smallest eigenvalue of a symmetric operator by Lanczos with full reorthogonalisation.

    Runs on the operator's device; the host sees only the tridiagonal coefficients, every
    10 steps from step 20, where it stops once the smallest Ritz value's residual bound
    ``beta_j |s_j|`` is below ``rtol`` times its magnitude. Ritz values lie inside the spectrum.

    Parameters
    ----------
    matvec : callable
        ``v -> A v`` for torch vectors of length ``n`` (``dtype`` on ``device``).
    n : int
        Operator size.
    max_steps : int
        Step limit (capped at ``n``).
    rtol : float
        Relative accuracy of the returned value.
    seed : int
        Seed of the random start vector.
    dtype, device
        Where the Lanczos vectors live.
    """
    steps = min(max_steps, n)
    V = torch.zeros(steps + 1, n, dtype=dtype, device=device)
    alpha = torch.zeros(steps, dtype=dtype, device=device)
    beta = torch.zeros_like(alpha)
    v = torch.as_tensor(np.random.default_rng(seed).standard_normal(n), dtype=dtype, device=device)
    V[0] = v / torch.linalg.vector_norm(v)
    for j in range(steps):
        w = matvec(V[j])
        alpha[j] = V[j] @ w
        for _ in range(2):                                  # twice is enough (Kahan)
            w = w - V[:j + 1].T @ (V[:j + 1] @ w)
        beta[j] = torch.linalg.vector_norm(w)
        V[j + 1] = w / beta[j]
        k = j + 1
        if k == steps or (k >= 20 and k % 10 == 0):
            a, b = alpha[:k].double().cpu().numpy(), beta[:k].double().cpu().numpy()
            tiny = np.flatnonzero(~(b > 1e-6 * np.nanmax(np.abs(a))))
            if tiny.size:                                   # invariant subspace: T is exact there
                m = tiny[0] + 1
                return float(_tridiagonal_eig(a[:m], b[:m - 1])[0][0])
            theta, s_ = _tridiagonal_eig(a, b[:-1])
            if k == steps or b[-1] * abs(s_[-1, 0]) <= rtol * abs(theta[0]):
                return float(theta[0])
    raise AssertionError("unreachable")


def _tridiagonal_eig(alpha, beta):
    return np.linalg.eigh(np.diag(alpha) + np.diag(beta, 1) + np.diag(beta, -1))


class HTP:
    """A loaded HTP network ready to build preconditioners for any N."""

    def __init__(self, net: HTPNet, provenance: dict | None = None, device="auto", threads: int | None = None):
        self.device = resolve_device(device)
        if threads:
            torch.set_num_threads(int(threads))
        self.net = net.to(self.device).eval()
        self.provenance = provenance or {}

    @classmethod
    def load(cls, path=None, device="auto", threads=None) -> "HTP":
        """Load a checkpoint (the shipped one when ``path`` is None)."""
        net, prov = checkpoint.load(path)
        return cls(net, prov, device, threads)

    @torch.no_grad()
    def setup(self, A, coords=None, density=None, ordering="auto", shift: float = 0.0,
              spd_guard: bool = True) -> Setup:
        """Order, partition, run the network and bind the factors to ``A``.

        Parameters
        ----------
        A : scipy sparse (N, N)
        coords, density : optional per-row geometry and density (caller's ordering)
        ordering : auto, morton, rcm or natural
        shift : extra diagonal term ``shift * D^-1`` added to M (SPD safety margin)
        spd_guard : estimate the most negative eigenvalue of D^1/2 M D^1/2 by Lanczos and, when
            it is negative, add ``1.2 |lambda_min| D^-1`` so that M is SPD (``Setup.guard_shift``)
        """
        t0 = time.perf_counter()
        A = sp.csr_matrix(A)
        n = A.shape[0]
        perm, name = choose_ordering(A, coords, ordering)
        Ap = A[perm][:, perm]
        part = self.net.cfg.partition(n)
        inp = build_input(Ap, part, None if coords is None else np.asarray(coords)[perm],
                          None if density is None else np.asarray(density)[perm]).to(self.device)
        packed = self.net(inp, part)
        if shift:
            packed[-part.n_pad:] += shift * inp.inv_diag
        pre = Setup(HTPOperator(packed, part), perm, name, 0.0, shift)
        if spd_guard and n > 1 and pre.factors_finite():
            lam = pre.min_scaled_eigenvalue(Ap.diagonal())
            if lam < 0:
                pre.guard_shift = 1.2 * -lam
                packed[-part.n_pad:] += pre.guard_shift * inp.inv_diag
        if self.device.type == "cuda":
            torch.cuda.synchronize()
        pre.setup_ms = 1e3 * (time.perf_counter() - t0)
        return pre
