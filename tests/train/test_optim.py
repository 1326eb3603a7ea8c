"""The trainers' Adam (eigs.train.optim.adam): fused on the CPU, and the same update as Adam's closed form."""

from __future__ import annotations

import torch

from eigs.train.optim import adam


def _reference_adam(p: torch.Tensor, grads: list[torch.Tensor], lr: float, eps: float) -> torch.Tensor:
    """Kingma & Ba's Adam in float64 (betas 0.9, 0.999, bias-corrected), one step per gradient."""
    p, m, v = p.double().clone(), torch.zeros_like(p, dtype=torch.float64), torch.zeros_like(p, dtype=torch.float64)
    for t, g in enumerate(grads, start=1):
        g = g.double()
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        p = p - lr * (m / (1 - 0.9**t)) / ((v / (1 - 0.999**t)).sqrt() + eps)
    return p


def test_fused_on_the_cpu_and_equal_to_the_closed_form():
    g = torch.Generator().manual_seed(0)
    a = torch.randn(1000, 3, generator=g).requires_grad_(True)
    b = torch.randn(64, generator=g).requires_grad_(True)
    start = [a.detach().clone(), b.detach().clone()]
    opt = adam([{"params": [a], "lr": 1e-2, "name": "a"}, {"params": [b], "lr": 3e-3}], eps=1e-15)
    assert opt.defaults["fused"] is True
    grads = [[torch.randn(a.shape, generator=g), torch.randn(b.shape, generator=g) * 1e-3] for _ in range(20)]
    for ga, gb in grads:
        a.grad, b.grad = ga.clone(), gb.clone()
        opt.step()
    ref_a = _reference_adam(start[0], [x[0] for x in grads], 1e-2, 1e-15)
    ref_b = _reference_adam(start[1], [x[1] for x in grads], 3e-3, 1e-15)
    torch.testing.assert_close(a.detach().double(), ref_a, rtol=0, atol=1e-6)
    torch.testing.assert_close(b.detach().double(), ref_b, rtol=0, atol=1e-6)


def test_a_group_added_later_steps_too():
    """The Gaussian trainer adds the method's groups (ADE, cameras) after building the optimizer."""
    x = torch.zeros(5, requires_grad=True)
    y = torch.zeros(3, requires_grad=True)
    opt = adam([x], lr=0.1)
    opt.add_param_group({"params": [y], "lr": 0.1})
    x.grad, y.grad = torch.ones(5), -torch.ones(3)
    opt.step()
    # Adam's first step moves every coordinate by lr against the gradient's sign (|m̂| / sqrt(v̂) = 1)
    torch.testing.assert_close(x.detach(), torch.full((5,), -0.1), rtol=0, atol=1e-6)
    torch.testing.assert_close(y.detach(), torch.full((3,), 0.1), rtol=0, atol=1e-6)


def test_not_fused_without_parameters_it_can_fuse():
    opt = adam([torch.zeros(3, dtype=torch.float64, requires_grad=True)], lr=0.1)
    assert opt.defaults["fused"] is True  # float64 on the CPU fuses too
    opt = adam([torch.zeros(3, dtype=torch.complex64, requires_grad=True)], lr=0.1)
    assert not opt.defaults["fused"] and opt.defaults["foreach"] is True


def test_finite_grads_finds_every_non_finite_entry() -> None:
    """One NaN, +inf or -inf anywhere in any gradient makes the check fail; finite gradients (huge ones included),
    parameters without a gradient and empty gradients pass."""
    from eigs.train.loop import finite_grads

    g = torch.Generator().manual_seed(0)
    params = [torch.zeros(s, requires_grad=True) for s in [(1000, 3), (7,), (256, 256), (0, 3), (5, 1, 3)]]
    for p in params:
        p.grad = torch.randn(p.shape, generator=g) * 1e30
    params.append(torch.zeros(3, requires_grad=True))  # no gradient
    assert finite_grads(params)
    for i in (0, 1, 2, 4):
        for bad in (float("nan"), float("inf"), -float("inf")):
            flat = params[i].grad.view(-1)
            k = int(torch.randint(flat.numel(), (1,), generator=g))
            keep = float(flat[k])
            flat[k] = bad
            assert not finite_grads(params), (i, bad)
            flat[k] = keep
    assert finite_grads(params) and finite_grads([])
