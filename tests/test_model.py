import dataclasses

import numpy as np
import pytest
import torch

from petsc_htp.paper.apply import Factors, assemble
from petsc_htp.paper.features import build_input
from petsc_htp.paper.model import HTPConfig, HTPNet
from petsc_htp.scenes.generator import make_frame


def test_default_size_matches_paper():
    net = HTPNet()
    assert 2.4e6 < net.n_params() < 2.9e6   # about 2.6 M parameters


@pytest.mark.parametrize("n", [100, 256, 300])
def test_forward_shapes_and_symmetric_m(tiny_cfg, n):
    torch.manual_seed(0)
    frame = make_frame(n, seed=3)
    net = HTPNet(tiny_cfg)
    part = tiny_cfg.partition(n)
    packed = net(build_input(frame.A, part, frame.coords, frame.rho), part)
    assert packed.shape == (part.packed_width,) and torch.isfinite(packed).all()
    M = assemble(Factors.unpack(packed.double(), part), part)
    np.testing.assert_allclose(M, M.T, atol=1e-6 * np.abs(M).max())


def test_one_set_of_weights_serves_every_n(tiny_cfg):
    """Forwards at other N neither add, reshape nor change weights, nor leave state behind."""
    torch.manual_seed(0)
    net = HTPNet(tiny_cfg).eval()
    before = {k: v.clone() for k, v in net.state_dict().items()}
    count = net.n_params()
    inputs = {}
    for n in (64, 300, 1000):
        frame, part = make_frame(n, seed=1), tiny_cfg.partition(n)
        inputs[n] = (build_input(frame.A, part, frame.coords, frame.rho), part)
    with torch.no_grad():
        first = net(*inputs[64])
        for n in (300, 1000):
            assert net(*inputs[n]).shape == (inputs[n][1].packed_width,)
        again = net(*inputs[64])
    after = net.state_dict()
    assert net.n_params() == count and after.keys() == before.keys()
    for k, v in before.items():
        assert torch.equal(after[k], v), k
    torch.testing.assert_close(again, first, rtol=0, atol=0)


def test_units_do_not_change_the_preconditioner(tiny_cfg):
    frame = make_frame(200, seed=1)
    net = HTPNet(tiny_cfg).eval()
    part = tiny_cfg.partition(200)
    with torch.no_grad():
        a = net(build_input(frame.A, part, frame.coords, frame.rho), part)
        b = net(build_input(1e3 * frame.A, part, frame.coords, frame.rho), part)
    fa, fb = Factors.unpack(a.double(), part), Factors.unpack(b.double(), part)
    np.testing.assert_allclose(1e3 * assemble(fb, part), assemble(fa, part), rtol=1e-3, atol=1e-6)


def test_invalid_config():
    with pytest.raises(ValueError, match="p_off"):
        HTPConfig(leaf=100, p_off=3).validate()
    with pytest.raises(ValueError, match="heads"):
        HTPConfig(d=30, heads=8).validate()
    net = HTPNet(dataclasses.replace(HTPConfig(d=32, heads=4, n_layers=1), leaf=32))
    with pytest.raises(ValueError, match="does not match"):
        frame = make_frame(256)
        part = HTPConfig().partition(256)
        net(build_input(frame.A, part), part)


def test_leaf_positions_are_centred_per_leaf_and_zero_without_geometry(tiny_cfg):
    fr = make_frame(300, seed=2)
    part = tiny_cfg.partition(fr.n)
    inp = build_input(fr.A, part, fr.coords, fr.rho)
    pos = inp.leaf_xy.view(part.n_leaves, part.leaf, 2)
    real = inp.mask.view(part.n_leaves, part.leaf)
    assert torch.all(pos[~real] == 0)
    sums = (pos * real[..., None]).sum(1)
    assert torch.allclose(sums, torch.zeros_like(sums), atol=1e-4)
    assert pos.abs().max() > 0.1
    assert torch.all(build_input(fr.A, part).leaf_xy == 0)
