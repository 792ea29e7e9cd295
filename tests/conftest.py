"""Shared pytest fixtures and markers for petsc_htp."""
import numpy as np
import pytest
import scipy.sparse as sp
import torch

requires_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


def grid_laplacian(nx, ny, dirichlet=0.0):
    """5-point Neumann Laplacian on an nx-by-ny grid (plus ``dirichlet`` on the diagonal)."""
    def path(m):
        t = sp.diags([-np.ones(m - 1), 2 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1]).tolil()
        t[0, 0] = t[m - 1, m - 1] = 1
        return t.tocsr()
    A = sp.kron(sp.eye(ny), path(nx)) + sp.kron(path(ny), sp.eye(nx)) + dirichlet * sp.eye(nx * ny)
    return sp.csr_matrix(A)


@pytest.fixture(scope="session")
def tiny_ckpt(tmp_path_factory):
    """A small untrained network checkpoint (its M starts out close to Jacobi)."""
    from petsc_htp.training import checkpoint
    from petsc_htp.paper.model import HTPConfig, HTPNet
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("ckpt") / "tiny.pt"
    checkpoint.save(path, HTPNet(HTPConfig(d=32, n_layers=1, heads=4)), {"note": "test"})
    return path


@pytest.fixture
def tiny_cfg():
    """A small network configuration that runs in milliseconds."""
    from petsc_htp.paper.model import HTPConfig
    return HTPConfig(d=32, n_layers=1, leaf=32, p_off=4, heads=4, n_gcn=1)
