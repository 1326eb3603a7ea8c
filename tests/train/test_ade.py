"""The ADE network's fused forward/backward (ade.FusedMLP, blocks of CHUNK_ROWS Gaussians, bias and ReLU in place)
against the same network through nn.Linear (ADE.forward_reference) with random cotangents, in float64 (equal to
rounding) and float32 (against the float64 reference), and the Function against finite differences."""

from __future__ import annotations

import pytest
import torch

from eigs.train import ade as ade_module
from eigs.train.ade import ADE, FusedMLP


def grads(net: ADE, x: torch.Tensor, pose: torch.Tensor, v: torch.Tensor, fused: bool) -> tuple[torch.Tensor, dict]:
    net.zero_grad(set_to_none=True)
    out = net(x, pose) if fused else net.forward_reference(x, pose)
    out.backward(v)
    return out.detach(), {n: p.grad.clone() for n, p in net.named_parameters()}


def make(depth: int, width: int, n: int, dtype: torch.dtype, seed: int = 0):  # noqa: ANN201
    torch.manual_seed(seed)
    net = ADE(n_latent=5, n_moved=4, width=width, depth=depth).to(dtype)
    for p in net.parameters():  # biases away from zero, so that every term of the gradient is exercised
        torch.nn.init.uniform_(p, -0.3, 0.3)
    x = torch.rand(n, 3, dtype=dtype) * 2 - 1
    pose = net.encode_poses(torch.eye(4, dtype=torch.float64).expand(5, 4, 4) + 0.1 * torch.rand(5, 4, 4)).to(dtype)
    v = torch.randn(n, 4, 3, dtype=dtype)
    return net, x, pose, v


@pytest.mark.parametrize("n", [0, 1, 1023, 1024, 2500])
@pytest.mark.parametrize(("depth", "width"), [(2, 32), (3, 64), (4, 48)])
def test_fused_equals_reference_in_float64(n, depth, width):
    net, x, pose, v = make(depth, width, n, torch.float64)
    out_f, g_f = grads(net, x, pose, v, fused=True)
    out_r, g_r = grads(net, x, pose, v, fused=False)
    assert out_f.shape == (n, 4, 3)
    torch.testing.assert_close(out_f, out_r, rtol=1e-12, atol=1e-12)
    for name in g_r:
        torch.testing.assert_close(g_f[name], g_r[name], rtol=1e-10, atol=1e-10, msg=name)


def test_fused_float32_within_1e5_of_float64_reference():
    net64, x, pose, v = make(3, 256, 3000, torch.float64)
    out_r, g_r = grads(net64, x, pose, v, fused=False)
    net32 = ADE(n_latent=5, n_moved=4, width=256, depth=3)
    net32.load_state_dict({k: t.float() for k, t in net64.state_dict().items()})
    out_f, g_f = grads(net32, x.float(), pose.float(), v.float(), fused=True)
    scale = out_r.abs().max()
    assert (out_f.double() - out_r).abs().max() <= 1e-5 * scale
    for name in g_r:
        err = (g_f[name].double() - g_r[name]).abs().max() / g_r[name].abs().max()
        assert err <= 1e-5, (name, float(err))


def test_blocks_do_not_change_the_result(monkeypatch):
    """A block size that splits the rows differently gives the same output and gradients (to float64 rounding)."""
    net, x, pose, v = make(3, 64, 700, torch.float64)
    ref = grads(net, x, pose, v, fused=True)
    monkeypatch.setattr(ade_module, "CHUNK_ROWS", 97)
    other = grads(net, x, pose, v, fused=True)
    torch.testing.assert_close(other[0], ref[0], rtol=1e-12, atol=1e-12)
    for name in ref[1]:
        torch.testing.assert_close(other[1][name], ref[1][name], rtol=1e-10, atol=1e-10)


def test_function_gradients_against_finite_differences(monkeypatch):
    """Every input, the activations' input included, in float64 against central differences (gradcheck)."""
    monkeypatch.setattr(ade_module, "CHUNK_ROWS", 4)  # several blocks in a small case
    torch.manual_seed(1)
    x = torch.randn(11, 5, dtype=torch.float64, requires_grad=True)
    shapes = [(7, 5), (6, 7), (3, 6)]
    params = []
    for out_dim, in_dim in shapes:
        params += [torch.randn(out_dim, in_dim, dtype=torch.float64, requires_grad=True),
                   torch.randn(out_dim, dtype=torch.float64, requires_grad=True)]  # fmt: skip
    assert torch.autograd.gradcheck(lambda *a: FusedMLP.apply(*a), (x, *params), eps=1e-6, atol=1e-6)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (absent on CI machines); runs on GPU hosts")
def test_fused_on_cuda_equals_cpu_reference():
    """On a GPU the network runs in one block; same network, same answer as the CPU reference (float64)."""
    net, x, pose, v = make(3, 64, 2500, torch.float64)
    out_r, g_r = grads(net, x, pose, v, fused=False)
    out_c, g_c = grads(net.cuda(), x.cuda(), pose.cuda(), v.cuda(), fused=True)
    torch.testing.assert_close(out_c.cpu(), out_r, rtol=1e-10, atol=1e-10)
    for name in g_r:
        torch.testing.assert_close(g_c[name].cpu(), g_r[name], rtol=1e-8, atol=1e-8)
