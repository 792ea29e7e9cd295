"""Tests of the PETSc-free inference helpers."""
import numpy as np
import torch

from petsc_htp.paper.inference import HTP, smallest_ritz_value
from petsc_htp.scenes.generator import make_frame


def _ritz(A, **kw):
    At = torch.as_tensor(A)
    return smallest_ritz_value(lambda v: At @ v, A.shape[0], **kw)


def test_smallest_ritz_value_finds_a_negative_outlier_and_stays_inside_the_spectrum():
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.standard_normal((300, 300)))
    eigs = np.concatenate([[-0.7], rng.uniform(0.1, 5.0, 299)])
    assert abs(_ritz((Q * eigs) @ Q.T) + 0.7) < 1e-6
    assert _ritz((Q * np.abs(eigs)) @ Q.T) >= 0.1 - 1e-9
    assert abs(_ritz(np.diag(eigs[:5])) + 0.7) < 1e-9                 # steps capped at n
    assert abs(_ritz(np.diag(np.repeat([-1.0, 2.0], 50))) + 1.0) < 1e-9   # invariant subspace after 2 steps


def test_min_scaled_eigenvalue_matches_the_dense_spectrum(tiny_ckpt):
    fr = make_frame(300, seed=3)
    pre = HTP.load(tiny_ckpt, device="cpu").setup(fr.A, fr.coords, fr.rho, spd_guard=False)
    sd = np.sqrt(fr.A.diagonal()[pre.perm])
    M = np.column_stack([pre.op.apply(e) for e in np.eye(fr.n)])
    exact = np.linalg.eigvalsh(sd[:, None] * (M + M.T) / 2 * sd[None, :])[0]
    assert abs(pre.min_scaled_eigenvalue(fr.A.diagonal()[pre.perm]) - exact) <= 0.02 * abs(exact) + 1e-5
