"""Tests of the PETSc-free inference helpers."""
import numpy as np

from petsc_htp.inference import smallest_ritz_value


def test_smallest_ritz_value_finds_a_negative_outlier_and_stays_inside_the_spectrum():
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.standard_normal((300, 300)))
    eigs = np.concatenate([[-0.7], rng.uniform(0.1, 5.0, 299)])
    A = (Q * eigs) @ Q.T
    assert abs(smallest_ritz_value(lambda v: A @ v, 300) + 0.7) < 1e-6
    spd = (Q * np.abs(eigs)) @ Q.T
    assert smallest_ritz_value(lambda v: spd @ v, 300) >= 0.1 - 1e-9
    assert abs(smallest_ritz_value(lambda v: np.diag(eigs[:5]) @ v, 5) + 0.7) < 1e-9   # steps capped at n
