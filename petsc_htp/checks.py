"""Setup-time checks shared by the preconditioner variants: is M finite and positive on random vectors?"""
import numpy as np


def min_rayleigh(apply, n: int, probes: int = 8, seed: int = 0) -> float:
    """Smallest Rayleigh quotient ``r^T M r / r^T r`` over random probes (< 0 proves M indefinite)."""
    rng = np.random.default_rng(seed)
    vals = []
    for _ in range(probes):
        r = rng.standard_normal(n)
        vals.append(float(r @ apply(r) / (r @ r)))
    return float(np.min(vals))


def probe_reason(apply, n: int, probes: int, name: str) -> str:
    """Empty when ``probes`` random Rayleigh quotients of M are finite and positive, else why not."""
    return rayleigh_reason(min_rayleigh(apply, n, probes) if probes else None, name)


def rayleigh_reason(lo, name: str) -> str:
    """Empty when the smallest probed Rayleigh quotient ``lo`` is finite and positive (None: no probe)."""
    if lo is None:
        return ""
    if not np.isfinite(lo):
        return f"{name} apply is not finite"
    if lo <= 0:
        return f"Rayleigh probe found M indefinite (min r^T M r / r^T r = {lo:.3e})"
    return ""


def check_message(prefix: str, reason: str, fallback: bool) -> str:
    """What HTPPC (options prefix ``prefix``) prints when its setup's checks failed for ``reason``: that it applies
    Jacobi instead (``fallback``), else a warning naming the option that would."""
    who = f"HTPPC{' (' + prefix + ')' if prefix else ''}"
    option = f"-{prefix}htp_fallback jacobi"
    if fallback:
        return f"{who}: {reason}; {option}: applying Jacobi (D^-1) instead"
    return f"{who}: WARNING: {reason}; Krylov methods will break down (use {option})"
