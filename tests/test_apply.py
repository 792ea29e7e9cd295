import numpy as np
import pytest
import torch

from petsc_htp.paper.apply import Factors, HTPOperator, TreeIndex, apply_flops, assemble, htp_apply
from petsc_htp.paper.partition import build_partition


def random_factors(n, leaf, coarse, seed=0):
    part = build_partition(n, leaf, coarse)
    gen = torch.Generator().manual_seed(seed)
    packed = torch.randn(part.packed_width, generator=gen, dtype=torch.float64)
    f = Factors.unpack(packed, part)
    for t in (f.F.view(-1, leaf), f.U.view(-1, coarse), f.V.view(-1, coarse)):
        t[n:] = 0
    f.g[n:] = 0
    return part, packed, f


@pytest.mark.parametrize("n,leaf,coarse", [(5, 8, 2), (64, 8, 2), (100, 16, 4), (300, 32, 8), (1000, 128, 32)])
def test_apply_equals_assembled(n, leaf, coarse):
    part, packed, f = random_factors(n, leaf, coarse)
    M = assemble(f, part)
    np.testing.assert_allclose(M, M.T, atol=1e-12)
    r = torch.zeros(part.n_pad, 3, dtype=torch.float64)
    r[:n] = torch.randn(n, 3, dtype=torch.float64)
    y = htp_apply(f, TreeIndex(part), r)[:n].numpy()
    np.testing.assert_allclose(y, M @ r[:n].numpy(), rtol=1e-10, atol=1e-9)
    op = HTPOperator(packed, part)
    np.testing.assert_allclose(op.apply(r[:n, 0].numpy()), M @ r[:n, 0].numpy(), rtol=1e-10, atol=1e-9)
    assert y[:, 0].shape == (n,)


def test_packed_width_checked():
    part = build_partition(64, 8, 2)
    with pytest.raises(ValueError, match="expected"):
        Factors.unpack(torch.zeros(part.packed_width + 1), part)


def test_float32_apply_returns_float64():
    part, packed, f = random_factors(300, 32, 8)
    op = HTPOperator(packed.float(), part)
    y = op.apply(np.ones(300))
    assert y.dtype == np.float64 and op.y.dtype == torch.float32
    np.testing.assert_allclose(y, assemble(f, part) @ np.ones(300), rtol=1e-4)


def test_memory_and_flops_linear_in_n():
    sizes = [1024, 2048, 4096, 8192, 16384]
    parts = [build_partition(n, 128, 32) for n in sizes]
    flops = [apply_flops(p) for p in parts]
    widths = [p.packed_width for p in parts]
    buffers = [HTPOperator(torch.zeros(p.packed_width), p).buffer_numel() for p in parts]
    for series in (flops, widths, buffers):
        per_n = np.array(series) / np.array(sizes)
        assert per_n.max() / per_n.min() < 1.05, series   # affine in N: no log N or N^2 term

