"""The ADE network's fused forward/backward (ade.FusedMLP, blocks of CHUNK_ROWS Gaussians, bias and ReLU in place)
against the same network through nn.Linear (ADE.forward_reference) with random cotangents, in float64 (equal to
rounding) and float32 (against the float64 reference), and the Function against finite differences."""

from __future__ import annotations

import pytest
import torch

from eigs.train.gaussian import ade as ade_module
from eigs.train.gaussian.ade import ADE, FusedMLP


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
    assert torch.autograd.gradcheck(lambda *a: FusedMLP.apply(a[0], None, *a[1:]), (x, *params), eps=1e-6, atol=1e-6)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU (absent on CI machines); runs on GPU hosts")
def test_fused_on_cuda_equals_cpu_reference():
    """On a GPU the network runs in one block; same network, same answer as the CPU reference (float64)."""
    net, x, pose, v = make(3, 64, 2500, torch.float64)
    out_r, g_r = grads(net, x, pose, v, fused=False)
    out_c, g_c = grads(net.cuda(), x.cuda(), pose.cuda(), v.cuda(), fused=True)
    torch.testing.assert_close(out_c.cpu(), out_r, rtol=1e-10, atol=1e-10)
    for name in g_r:
        torch.testing.assert_close(g_c[name].cpu(), g_r[name], rtol=1e-8, atol=1e-8)


def bf16(t: torch.Tensor) -> torch.Tensor:
    """``t`` rounded to bfloat16 (round to nearest even), back in float64."""
    return t.to(torch.bfloat16).double()


def emulated_bf16(net: ADE, x: torch.Tensor, pose: torch.Tensor, v: torch.Tensor) -> tuple[torch.Tensor, dict]:
    """The bfloat16 algorithm of FusedMLP in float64: inputs, weights, biases, every product's result and the
    cotangent rounded to bfloat16 at the points the kernel rounds them, products and sums exact."""
    layers = [net.first_x, *net.hidden, net.last]
    ws = [bf16(layer.weight.detach().double()) for layer in layers]
    bias0 = net.first_x.bias.detach().double() + net.first_pose(pose).detach().double()
    bs = [bf16(bias0)] + [bf16(layer.bias.detach().double()) for layer in layers[1:]]
    h = [bf16(ade_module.frequency_encoding(x, net.x_freqs).double())]
    for w, b in zip(ws[:-1], bs[:-1], strict=True):
        h.append(bf16(torch.relu(h[-1] @ w.t() + b)))
    out = bf16(h[-1] @ ws[-1].t() + bs[-1])
    g = bf16(v.reshape(out.shape).double())
    gw, gb = [None] * len(ws), [None] * len(ws)
    for k in range(len(ws) - 1, -1, -1):
        gw[k], gb[k] = g.t() @ h[k], g.sum(0)
        if k > 0:
            g = bf16(g @ ws[k]) * (h[k] > 0)
    names = ["first_x", *[f"hidden.{i}" for i in range(len(net.hidden))], "last"]
    grads_ = {f"{n}.weight": gw[i] for i, n in enumerate(names)} | {f"{n}.bias": gb[i] for i, n in enumerate(names)}
    return out.reshape(v.shape), grads_


@pytest.mark.parametrize(("depth", "width", "n"), [(2, 64, 5000), (3, 256, 3000), (4, 128, 9000)])
def test_bfloat16_matches_its_float64_emulation_and_the_exact_output(depth, width, n):
    """Mixed precision (bfloat16 products, float32 parameters): the output and the parameter gradients equal a float64
    emulation of the same rounding points to 5e-3 (relative, norm: the kernel's float32 accumulation and the
    block-wise rounding of weight-gradient partial sums), and the output is within 2e-2 of the exact float64 network's
    largest entry. The gradients are not compared with the exact network's: where bfloat16 rounding flips the sign
    of a pre-activation near zero, ReLU routes that unit's whole gradient differently (measured: 4-10 % in norm
    on these random networks), as in any bfloat16 training."""
    net64, x, pose, v = make(depth, width, n, torch.float64)
    out_exact, _ = grads(net64, x, pose, v, fused=False)
    net = ADE(n_latent=5, n_moved=4, width=width, depth=depth, matmul_dtype=torch.bfloat16)
    net.load_state_dict({k: t.float() for k, t in net64.state_dict().items()})
    out, g = grads(net, x.float(), pose.float(), v.float(), fused=True)
    assert out.dtype == torch.float32 and all(t.dtype == torch.float32 for t in g.values())
    out_em, g_em = emulated_bf16(net, x.float(), pose.float(), v.float())
    assert (out.double() - out_em).norm() <= 5e-3 * out_em.norm()
    assert (out.double() - out_exact).abs().max() <= 2e-2 * out_exact.abs().max()
    g.pop("first_pose.weight")  # the pose half of the first layer: its gradient is first_x.bias's (outer product)
    for name, ref in g_em.items():
        err = (g[name].double() - ref).norm() / ref.norm()
        assert err <= 5e-3, (name, float(err))


def test_precision_option():
    cpu = torch.device("cpu")
    assert ade_module.compute_dtype("float32", cpu) is None
    assert ade_module.compute_dtype("bfloat16", cpu) is torch.bfloat16
    native = ade_module.bf16_matmul_is_native(cpu)
    assert ade_module.compute_dtype("auto", cpu) is (torch.bfloat16 if native else None)
    with pytest.raises(ValueError, match="float16"):
        ade_module.compute_dtype("float16", cpu)


@pytest.mark.parametrize("n", [0, 1, 4097])
def test_bfloat16_edge_sizes(n):
    """No rows, one row, and one row past a bfloat16 block: float32 outputs and gradients, finite, the right shapes,
    and the output within 2e-2 of the float32 network's largest entry."""
    net, x, pose, v = make(3, 64, n, torch.float32)
    ref, _ = grads(net, x, pose, v, fused=True)
    net.matmul_dtype = torch.bfloat16
    out, g = grads(net, x, pose, v, fused=True)
    assert out.shape == (n, 4, 3) and out.dtype == torch.float32
    assert all(t.dtype == torch.float32 and bool(torch.isfinite(t).all()) for t in g.values())
    if n:
        assert (out - ref).abs().max() <= 2e-2 * ref.abs().max()


@pytest.mark.skipif(not ade_module.linear_relu_is_fused(torch.device("cpu")),
                    reason="needs a CPU with native bfloat16 products (AMX or AVX512-BF16) for oneDNN's fused linear")
@pytest.mark.parametrize("n", [1, 5000])
def test_bfloat16_fused_linear_relu_equals_addmm_then_relu(monkeypatch, n):
    """oneDNN's linear with bias and ReLU fused gives the same output and gradients as addmm + relu_, bit for bit."""
    net, x, pose, v = make(3, 256, n, torch.float32)
    net.matmul_dtype = torch.bfloat16
    fused = grads(net, x, pose, v, fused=True)
    monkeypatch.setattr(ade_module, "linear_relu_is_fused", lambda device: False)
    plain = grads(net, x, pose, v, fused=True)
    assert torch.equal(fused[0], plain[0])
    for name in plain[1]:
        assert torch.equal(fused[1][name], plain[1][name]), name
