import pytest
import torch

from petsc_htp.training.loss import cosine_loss, n_probes, sai_loss, smoothed_probes
from tests.conftest import grid_laplacian


@pytest.fixture
def spd():
    A = grid_laplacian(6, 5, dirichlet=0.3).toarray()
    return torch.tensor(A)


@pytest.mark.parametrize("alpha", [1e-6, 0.01, 1.0, 7.5, 1e5])
def test_cosine_loss_invariant_to_positive_scaling(spd, alpha):
    gen = torch.Generator().manual_seed(int(alpha * 1000) % 97)
    B = torch.randn(30, 30, generator=gen, dtype=torch.float64)
    M = B @ B.T + torch.eye(30, dtype=torch.float64)
    Z = torch.randn(30, 8, generator=gen, dtype=torch.float64)
    AZ = spd @ Z
    base = cosine_loss(Z, AZ, lambda X: M @ X)
    scaled = cosine_loss(Z, AZ, lambda X: alpha * M @ X)
    assert 0 < float(base) < 2
    assert float(scaled) == pytest.approx(float(base), rel=1e-9, abs=1e-12)


def test_cosine_loss_zero_for_exact_inverse(spd):
    Z = torch.randn(30, 16, dtype=torch.float64)
    inv = torch.linalg.inv(spd)
    assert abs(float(cosine_loss(Z, spd @ Z, lambda X: inv @ X))) < 1e-12
    # and the SAI loss is zero there too once scaled to ||A||, but not scale-invariant
    a_norm = float(torch.linalg.matrix_norm(spd, ord=2))
    assert float(sai_loss(Z, spd, lambda X: a_norm * inv @ X, a_norm)) < 1e-20
    assert float(sai_loss(Z, spd, lambda X: 2 * a_norm * inv @ X, a_norm)) > 0.5


def test_probe_count_and_smoothing_lowers_energy():
    assert n_probes(100) == 64 and n_probes(16384) == 128 and n_probes(5000) == 71
    A = torch.tensor(grid_laplacian(16, 16).toarray()).float().to_sparse()
    inv_diag = 1 / torch.tensor(grid_laplacian(16, 16).diagonal()).float()
    mask = torch.ones(256, dtype=torch.bool)
    raw = smoothed_probes(A, inv_diag, mask, 32, steps=0, generator=torch.Generator().manual_seed(0))
    smooth = smoothed_probes(A, inv_diag, mask, 32, generator=torch.Generator().manual_seed(0))
    rayleigh = lambda Z: float((Z * (A @ Z)).sum() / (Z * Z).sum())  # noqa: E731
    assert rayleigh(smooth) < 0.6 * rayleigh(raw)      # energy moved toward low frequencies
    assert not smooth.requires_grad
