"""Training objectives of both networks: the cosine-Hutchinson probe loss and the SAI loss.

Both take the probes Z, the fixed products AZ (no gradient through A) and a
callable ``apply_m`` that maps a block of vectors to M times it.
"""
from __future__ import annotations

import math

import torch


def n_probes(n: int) -> int:
    """K_z = max(64, ceil(sqrt(N)))."""
    return max(64, math.ceil(math.sqrt(n)))


def spmm(A: torch.Tensor, X: torch.Tensor) -> torch.Tensor:
    """Sparse A times dense X, detached from autograd."""
    with torch.no_grad():
        return A @ X


def smoothed_probes(A: torch.Tensor, inv_diag: torch.Tensor, mask: torch.Tensor, k: int,
                    steps: int = 2, omega: float = 0.6, generator=None) -> torch.Tensor:
    """Gaussian probes low-pass filtered by damped Jacobi: z <- z - omega D^-1 A z.

    Parameters
    ----------
    A : sparse tensor (N_pad, N_pad)
    inv_diag : (N_pad,) 1/diag(A), zero on padding
    mask : (N_pad,) bool, real indices
    k : number of probes
    """
    Z = torch.randn(A.shape[0], k, generator=generator, device=inv_diag.device) * mask[:, None]
    for _ in range(steps):
        Z = Z - omega * inv_diag[:, None] * spmm(A, Z)
    return Z.detach()


def cosine_loss(Z: torch.Tensor, AZ: torch.Tensor, apply_m) -> torch.Tensor:
    """L = 1 - <Z, M A Z>_F / (||Z||_F ||M A Z||_F); invariant to positive scaling of M."""
    Y = apply_m(AZ)
    return 1.0 - (Z * Y).sum() / (Z.norm() * Y.norm()).clamp_min(1e-30)


def sai_loss(Z: torch.Tensor, A: torch.Tensor, apply_m, a_norm: float) -> torch.Tensor:
    """L = ||A M Z / ||A|| - Z||_F^2 / ||Z||_F^2 (normalised by the probe energy)."""
    MZ = apply_m(Z)
    AMZ = A @ MZ
    return (AMZ / a_norm - Z).square().sum() / Z.square().sum()


LOSSES = {"cosine", "sai"}
