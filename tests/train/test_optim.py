"""The trainers' Adam (eigs.train.optim.adam): fused on the CPU, and the same update as Adam's closed form."""

from __future__ import annotations

import io
import subprocess
import sys

import pytest
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
    grid = torch.zeros((1, 4, 3, 5, 6), requires_grad=True)  # a field's grid gradient: channels last, not contiguous
    grid.grad = torch.randn(grid.shape, generator=g).contiguous(memory_format=torch.channels_last_3d)
    params.append(grid)
    params.append(torch.zeros(3, requires_grad=True))  # no gradient
    assert finite_grads(params)
    for i in (0, 1, 2, 4, 5):
        for bad in (float("nan"), float("inf"), -float("inf")):
            grad = params[i].grad
            k = tuple(int(torch.randint(n, (1,), generator=g)) for n in grad.shape)
            keep = float(grad[k])
            grad[k] = bad
            assert not finite_grads(params), (i, bad)
            grad[k] = keep
    assert finite_grads(params) and finite_grads([])


def _params(seed: int) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    shapes = [(500, 3), (500, 1, 3), (64,), (7, 5)]
    return [torch.randn(s, generator=g).requires_grad_(True) for s in shapes]


def _groups(params: list[torch.Tensor]) -> list[dict]:
    """Named groups with their own learning rates, as the Gaussian trainer makes them; the last added later."""
    return [{"params": [p], "lr": 10.0 ** -(i + 1), "name": f"p{i}"} for i, p in enumerate(params[:-1])]


def _run(opt, params: list[torch.Tensor], steps: range, seed: int) -> None:
    """Steps with random gradients, one parameter without a gradient every third step, the first group's learning
    rate decaying (as the means' does)."""
    g = torch.Generator().manual_seed(seed)
    for t in steps:
        for i, p in enumerate(params):
            p.grad = None if (t % 3 == 2 and i == 1) else torch.randn(p.shape, generator=g) * 10.0 ** (i - 2)
        opt.param_groups[0]["lr"] = 0.1 * 0.9**t
        opt.step()


def test_fused_adam_is_torch_fused_adam_bit_for_bit():
    """FusedAdam against torch.optim.Adam(fused=True): parameters, moments and step counts equal exactly after 12
    steps with per-group learning rates, a decaying rate, a group added after construction and missing gradients."""
    from eigs.train.optim import FusedAdam

    ours, theirs = _params(1), _params(1)
    opt_ours = FusedAdam(_groups(ours), eps=1e-15)
    opt_theirs = torch.optim.Adam(_groups(theirs), eps=1e-15, fused=True)
    opt_ours.add_param_group({"params": [ours[-1]], "lr": 3e-3})
    opt_theirs.add_param_group({"params": [theirs[-1]], "lr": 3e-3})
    _run(opt_ours, ours, range(12), seed=2)
    _run(opt_theirs, theirs, range(12), seed=2)
    for a, b in zip(ours, theirs, strict=True):
        assert torch.equal(a, b)
        for key in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(opt_ours.state[a][key], opt_theirs.state[b][key]), key
    assert opt_ours.state[ours[1]]["step"].item() == 8  # no gradient on 4 of the 12 steps: no update, no count
    assert opt_ours.state[ours[1]]["step"].dtype == torch.float32


def test_fused_adam_state_dict_loads_both_ways():
    """A torch.optim.Adam checkpoint resumes in FusedAdam and the reverse, and the continued runs are equal bit for
    bit to one uninterrupted run; the state_dicts have the same groups, keys and numbering."""
    from eigs.train.optim import FusedAdam

    straight = _params(3)
    opt = torch.optim.Adam(_groups(straight) + [{"params": [straight[-1]], "lr": 3e-3}], eps=1e-15, fused=True)
    _run(opt, straight, range(10), seed=4)

    for first, second in ((torch.optim.Adam, FusedAdam), (FusedAdam, torch.optim.Adam)):
        params = _params(3)
        extra = {"fused": True} if first is torch.optim.Adam else {}
        a = first(_groups(params) + [{"params": [params[-1]], "lr": 3e-3}], eps=1e-15, **extra)
        _run(a, params, range(5), seed=4)  # the same first five gradients as `straight` saw
        buf = io.BytesIO()  # a round trip through torch.save, as a checkpoint makes
        torch.save({"opt": a.state_dict(), "params": [p.detach() for p in params]}, buf)
        buf.seek(0)
        loaded = torch.load(buf, weights_only=True)
        resumed = [p.clone().requires_grad_(True) for p in loaded["params"]]
        extra = {"fused": True} if second is torch.optim.Adam else {}
        b = second(_groups(resumed) + [{"params": [resumed[-1]], "lr": 1.0}], eps=1e-3, **extra)
        b.load_state_dict(loaded["opt"])
        assert [g["lr"] for g in b.param_groups][-1] == 3e-3 and b.param_groups[0]["eps"] == 1e-15  # from the file
        assert b.param_groups[0]["name"] == "p0" and b.param_groups[0]["params"][0] is resumed[0]
        g = torch.Generator().manual_seed(4)  # replay the gradient stream up to step 5, then continue
        for t in range(5):
            for i, p in enumerate(resumed):
                if not (t % 3 == 2 and i == 1):
                    torch.randn(p.shape, generator=g)
        for t in range(5, 10):
            for i, p in enumerate(resumed):
                p.grad = None if (t % 3 == 2 and i == 1) else torch.randn(p.shape, generator=g) * 10.0 ** (i - 2)
            b.param_groups[0]["lr"] = 0.1 * 0.9**t
            b.step()
        for x, y in zip(resumed, straight, strict=True):
            assert torch.equal(x, y), (first.__name__, second.__name__)
        ours, theirs = (a, b) if first is FusedAdam else (b, a)
        sd_ours, sd_theirs = ours.state_dict(), theirs.state_dict()

        def options(sd: dict) -> list[dict]:
            return [{k: v for k, v in grp.items() if k != "lr"} for grp in sd["param_groups"]]  # lr: a's is older

        assert options(sd_ours) == options(sd_theirs)
        assert sorted(sd_ours["state"]) == sorted(sd_theirs["state"]) == [0, 1, 2, 3]


def test_fused_adam_refuses_what_it_cannot_step():
    from eigs.train.optim import FusedAdam

    x = torch.zeros(3, requires_grad=True)
    with pytest.raises(ValueError, match="empty parameter list"):
        FusedAdam([])
    with pytest.raises(ValueError, match="more than one parameter group"):
        FusedAdam([{"params": [x]}, {"params": [x]}])
    with pytest.raises(TypeError, match="floating tensors"):
        FusedAdam([torch.zeros(3, dtype=torch.int64)])
    opt = FusedAdam([x])
    with pytest.raises(ValueError, match="number of parameter groups"):
        opt.load_state_dict({"state": {}, "param_groups": []})
    x.grad = torch.ones(3)
    opt.zero_grad(set_to_none=False)
    assert torch.equal(x.grad, torch.zeros(3))
    opt.zero_grad()
    assert x.grad is None


def test_a_training_process_does_not_import_the_compiler():
    """Building the trainers' Adam and stepping it leaves torch._dynamo unimported (seconds of every process start),
    in a fresh interpreter."""
    code = (
        "import sys, torch\n"
        "from eigs.train.optim import adam\n"
        "x = torch.zeros(3, requires_grad=True)\n"
        "opt = adam([{'params': [x], 'lr': 0.1, 'name': 'x'}], eps=1e-15)\n"
        "x.grad = torch.ones(3); opt.step(); opt.zero_grad(); opt.load_state_dict(opt.state_dict())\n"
        "assert 'torch._dynamo' not in sys.modules, 'torch._dynamo imported'\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    probe = subprocess.run(
        [sys.executable, "-c", "import sys, torch\ntorch.optim.Adam([torch.zeros(1, requires_grad=True)])\n"
         "print('torch._dynamo' in sys.modules)"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert probe.stdout.strip() == "True"  # the check above can fail: torch's own Adam does import it


def test_moments_consistent_bound_is_attained_and_holds_on_adam_histories():
    """The bound |m| ≤ C·√v of eigs.train.optim.moments_consistent: the gradient history g_{t−j} = (β1/β2)^j (the
    Cauchy–Schwarz equality case) approaches C in float64 (closed form), 1 % past it is refused, and FusedAdam's
    float32 moments after 400 steps of assorted gradients (heavy-tailed, sign-flipping, zero, 1e-25) keep it."""
    import math

    from eigs.train.optim import FusedAdam, moments_consistent

    b1, b2 = 0.9, 0.999
    c = (1 - b1) / math.sqrt((1 - b2) * (1 - b1 * b1 / b2))
    t = 4000
    g = torch.tensor([(b1 / b2) ** j for j in range(t)], dtype=torch.float64)  # g_{t-j}
    m = (1 - b1) * (b1 ** torch.arange(t, dtype=torch.float64) * g).sum()
    v = (1 - b2) * (b2 ** torch.arange(t, dtype=torch.float64) * g * g).sum()
    assert abs(float(m / v.sqrt()) / c - 1) < 1e-6
    assert moments_consistent(m.reshape(1), v.reshape(1), (b1, b2), 0.0)
    assert not moments_consistent(1.01 * m.reshape(1), v.reshape(1), (b1, b2), 0.0)
    assert moments_consistent(torch.tensor([5.0]), torch.tensor([1.0]), (0.9, 0.5), 0.0)  # β1² ≥ β2: no bound

    gen = torch.Generator().manual_seed(0)
    p = torch.zeros(6, 1000, requires_grad=True)
    opt = FusedAdam([p], lr=1e-2, eps=1e-15)
    for step in range(400):
        grad = torch.randn(6, 1000, generator=gen)
        grad[0] = grad[0] ** 3 * 100  # heavy-tailed
        grad[1] = (-1.0) ** step * grad[1].abs()  # alternating sign
        grad[2] = 0.0 if step > 50 else grad[2]  # stops: both moments decay
        grad[3] *= 1e-25  # squares underflow in float32
        grad[4] = 1.0  # constant
        p.grad = grad
        opt.step()
        state = opt.state[p]
        if step % 20 == 0 or step == 399:
            assert moments_consistent(state["exp_avg"], state["exp_avg_sq"], (b1, b2), 1e-15), step
    bad = state["exp_avg"].clone()
    bad[1, 7] = 3e36  # what a damaged checkpoint can hold
    assert not moments_consistent(bad, state["exp_avg_sq"], (b1, b2), 1e-15)
