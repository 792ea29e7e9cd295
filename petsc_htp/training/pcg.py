"""A plain float64 preconditioned CG in NumPy, with breakdown detection.

It is the reference solver for training-time evaluation and tests; PETSc's KSP
is what users run.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class CGResult:
    """Outcome of :func:`pcg`."""

    x: np.ndarray
    iterations: int
    reason: str          # "converged", "max_it", "indefinite_pc", "indefinite_mat", "nan"
    history: list = field(default_factory=list)

    @property
    def converged(self) -> bool:
        """True when the tolerance was reached."""
        return self.reason == "converged"


def pcg(A, b, apply_m=None, rtol=1e-8, maxiter=10000) -> CGResult:
    """Solve A x = b by PCG from x0 = 0; stop when ||r_k|| <= rtol ||r_0||.

    Parameters
    ----------
    A : sparse matrix or LinearOperator-like with ``@``
    b : ndarray
    apply_m : callable r -> M r, optional (identity when None)
    """
    x = np.zeros_like(b, dtype=np.float64)
    r = np.array(b, dtype=np.float64)
    r0 = np.linalg.norm(r)
    hist = [r0]
    if r0 == 0:
        return CGResult(x, 0, "converged", hist)
    z = apply_m(r) if apply_m else r.copy()
    rz = r @ z
    p = z.copy()
    for k in range(1, maxiter + 1):
        if not np.isfinite(rz):
            return CGResult(x, k - 1, "nan", hist)
        if rz <= 0:
            return CGResult(x, k - 1, "indefinite_pc", hist)
        Ap = A @ p
        pAp = p @ Ap
        if pAp <= 0:
            return CGResult(x, k - 1, "indefinite_mat", hist)
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        rn = np.linalg.norm(r)
        hist.append(rn)
        if rn <= rtol * r0:
            return CGResult(x, k, "converged", hist)
        z = apply_m(r) if apply_m else r.copy()
        rz_new = r @ z
        p = z + (rz_new / rz) * p
        rz = rz_new
    return CGResult(x, maxiter, "max_it", hist)


def jacobi(A):
    """Return r -> D^-1 r for the diagonal of A."""
    inv = 1.0 / A.diagonal()
    return lambda r: inv * r
