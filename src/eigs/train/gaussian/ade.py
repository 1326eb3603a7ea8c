"""EiGS's Adaptive Deviation Estimator (paper §III-A, Eq. 1): an MLP predicting, for every Gaussian, its
displacements at the N moved latent times of a view.

Inputs: the frequency encoding γ of each Gaussian's centre (detached) and of the view's N+1 latent poses. A pose
is encoded by its translation and the first two columns of its rotation (the continuous 6-D rotation
representation of Zhou et al., CVPR 2019): 9 numbers, γ-encoded, concatenated over k = 0..N.

The pose encoding is the same for every Gaussian of a view, so its product with the first layer is folded into a
per-view bias instead of concatenating it to each Gaussian's input: ``first_x(γ(x_j)) + first_pose(γ(P))`` equals
the first layer on the concatenation exactly, and costs one (pose inputs × width) product per step instead of one
per Gaussian.

The layers run as one autograd Function, :class:`FusedMLP`, over blocks of ``CHUNK_ROWS`` Gaussians: bias and ReLU
are applied in place on each block's activations while they are in cache, and the backward accumulates the weight
gradients block by block. :meth:`ADE.forward_reference` is the same network through ``nn.Linear`` and
``torch.relu`` (the reference the tests compare it with; equal up to float32 summation order, ~1e-6 relative).
On the 2-core VM at 17k Gaussians, width 256, one thread: forward + backward 115 ms instead of 124–132 ms.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from eigs.train.gaussian.options import PRECISIONS

CHUNK_ROWS = 1024  # Gaussians per block of FusedMLP (1024–2048 measured fastest; 4096 and whole-array slower)
CHUNK_ROWS_BF16 = 4096  # the same in bfloat16 (AMX, 17k rows, one thread: 1024 43 ms, 2048 35, 4096 33, all 51)


def frequency_encoding(p: Tensor, n_freqs: int) -> Tensor:
    """γ(p) = [p, sin(2ᵏπp), cos(2ᵏπp)]ₖ₌₀..ₙ₋₁ along the last axis: (…, D) → (…, D·(1 + 2·n_freqs))."""
    if n_freqs == 0:
        return p
    freqs = (2.0 ** torch.arange(n_freqs, dtype=p.dtype, device=p.device)) * math.pi  # (F,)
    a = p.unsqueeze(-1) * freqs  # (…, D, F)
    return torch.cat([p, torch.sin(a).flatten(-2), torch.cos(a).flatten(-2)], dim=-1)


def pose_features(c2w: Tensor) -> Tensor:
    """(…, 4, 4) camera-to-world → (…, 9): translation, then the first two rotation columns."""
    return torch.cat([c2w[..., :3, 3], c2w[..., :3, 0], c2w[..., :3, 1]], dim=-1)


def block_rows(x: Tensor) -> int:
    """Rows per block: ``CHUNK_ROWS`` (``CHUNK_ROWS_BF16`` for bfloat16 ``x``) on the CPU (cache-sized blocks), all
    rows at once on a GPU."""
    if x.device.type != "cpu":
        return max(1, x.shape[0])
    return CHUNK_ROWS_BF16 if x.dtype == torch.bfloat16 else CHUNK_ROWS


def bf16_matmul_is_native(device: torch.device) -> bool:
    """Whether bfloat16 matrix products run in hardware on ``device``: a CPU with AMX tiles or AVX512-BF16 (oneDNN
    uses them), or a CUDA GPU that supports bfloat16. Elsewhere bfloat16 is emulated and slower than float32."""
    if device.type == "cuda":
        return bool(torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return False
    cpu = torch.cpu
    checks = ("_is_amx_tile_supported", "_is_avx512_bf16_supported")
    return any(bool(getattr(cpu, name, lambda: False)()) for name in checks)


def compute_dtype(precision: str, device: torch.device) -> torch.dtype | None:
    """The dtype the ADE's matrix products run in for option ``precision`` (:data:`PRECISIONS`): None = the
    parameters' own dtype (float32), ``torch.bfloat16`` for ``bfloat16``, and for ``auto`` bfloat16 where
    :func:`bf16_matmul_is_native`, else None."""
    if precision not in PRECISIONS:
        raise ValueError(f"ADE precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    if precision == "bfloat16" or (precision == "auto" and bf16_matmul_is_native(device)):
        return torch.bfloat16
    return None


_linear_pointwise = getattr(getattr(torch.ops, "mkldnn", None), "_linear_pointwise", None)


def linear_relu_is_fused(device: torch.device) -> bool:
    """Whether :class:`FusedMLP` runs its bfloat16 hidden layers through oneDNN's linear with the bias and ReLU
    fused (``torch.ops.mkldnn._linear_pointwise``): on a CPU with native bfloat16 products, where the op exists.
    One pass instead of addmm's bias copy, product and ReLU, the same values bit for bit (tests/train/test_ade.py):
    on the Xeon (AMX, 2 threads), 10,000 Gaussians, width 256, depth 3, the three layers' products alone take 3.0 ms
    instead of 8.9, the ADE's forward 5.9 ms instead of 7.8 and its forward + backward 23.4 instead of 25.7 (medians
    of six interleaved rounds)."""
    return (_linear_pointwise is not None and torch.backends.mkldnn.is_available() and device.type == "cpu"
            and bf16_matmul_is_native(device))  # fmt: skip


class FusedMLP(torch.autograd.Function):
    """``x`` (N, I) through linear layers ``(W_0, b_0, …, W_{L-1}, b_{L-1})`` (W_l: (out, in)) with ReLU between:
    (N, out_{L-1}) in ``x``'s dtype. The forward keeps every hidden activation (after ReLU) for the backward; ReLU's
    derivative is read from them (an activation > 0 ⟺ its pre-activation > 0).

    ``dtype``: the dtype of the matrix products and of the kept activations (None: ``x``'s own). With
    ``torch.bfloat16`` (mixed precision) the products accumulate in float32 inside the kernel and round their
    results to bfloat16 (8 significant bits); the output, ``v_x`` and the parameter gradients are returned in the
    parameters' dtype, the weight gradients summed over blocks in it. Promised: relative error ≤ 2e-2 of the
    largest entry (tests/train/test_ade.py measures it against float64)."""

    @staticmethod
    def forward(ctx, x: Tensor, dtype: torch.dtype | None, *params: Tensor) -> Tensor:  # noqa: ANN001
        cd = dtype or x.dtype
        weights = [w.to(cd) for w in params[0::2]]
        biases = [b.to(cd) for b in params[1::2]]
        xc = x.to(cd)
        n = x.shape[0]
        rows = block_rows(xc)
        fused = cd == torch.bfloat16 and linear_relu_is_fused(xc.device)
        acts: list[list[Tensor]] = [[] for _ in weights[:-1]]  # per hidden activation, its (rows, width) blocks
        out = x.new_empty(n, weights[-1].shape[0])
        last = xc.new_empty(min(rows, n), weights[-1].shape[0]) if cd != x.dtype else None
        for s in range(0, n, rows):
            h = xc[s : s + rows]
            for layer, (w, b) in enumerate(zip(weights, biases, strict=True)):
                if layer < len(acts):
                    h = _linear_pointwise(h, w, b, "relu", [], "") if fused else torch.addmm(b, h, w.t()).relu_()
                    acts[layer].append(h)
                elif last is None:
                    torch.addmm(b, h, w.t(), out=out[s : s + rows])
                else:
                    out[s : s + rows] = torch.addmm(b, h, w.t(), out=last[: h.shape[0]])
        ctx.save_for_backward(xc, *(blk for layer in acts for blk in layer), *weights)
        ctx.n_layers = len(weights)
        ctx.param_dtype = params[0].dtype
        return out

    @staticmethod
    def backward(ctx, v_out: Tensor) -> tuple[Tensor | None, ...]:  # noqa: ANN001
        saved = ctx.saved_tensors
        n_layers = ctx.n_layers
        x, weights = saved[0], saved[len(saved) - n_layers :]
        blocks = saved[1 : len(saved) - n_layers]  # the hidden activations' blocks, layer after layer
        n_blocks = len(blocks) // max(1, n_layers - 1)
        cd, pd = x.dtype, ctx.param_dtype
        v_w = [torch.zeros(w.shape, dtype=pd, device=w.device) for w in weights]
        v_b = [torch.zeros(w.shape[0], dtype=pd, device=w.device) for w in weights]
        v_x = torch.empty(x.shape, dtype=v_out.dtype, device=x.device) if ctx.needs_input_grad[0] else None
        v_out = v_out.to(cd).contiguous()
        rows = block_rows(x)
        for i, s in enumerate(range(0, x.shape[0], rows)):
            g = v_out[s : s + rows]  # gradient at the current layer's output
            inputs = [x[s : s + rows]] + [blocks[layer * n_blocks + i] for layer in range(n_layers - 1)]
            for layer in range(n_layers - 1, -1, -1):
                a = inputs[layer]
                if cd == pd:
                    v_w[layer].addmm_(g.t(), a)
                else:  # a block's product in the compute dtype, summed over blocks in the parameters' dtype
                    v_w[layer] += torch.mm(g.t(), a)
                v_b[layer] += g.sum(dim=0)  # accumulated in float32 by the kernel whatever g's dtype
                if layer > 0:  # ReLU's backward in one pass: g·W where the activation is > 0, else 0
                    g = torch.ops.aten.threshold_backward(g @ weights[layer], a, 0)
                elif v_x is not None:
                    if cd == v_x.dtype:
                        torch.mm(g, weights[0], out=v_x[s : s + rows])
                    else:
                        v_x[s : s + rows] = g @ weights[0]
        grads: list[Tensor | None] = [v_x, None]
        for w, b in zip(v_w, v_b, strict=True):
            grads += [w, b]
        return tuple(grads)


class ADE(nn.Module):
    """MLP of ``depth`` linear layers (ReLU between, Xavier-uniform weights, zero biases) mapping γ(x) and γ(poses)
    to ``n_moved`` × ``out_per_latent`` outputs per Gaussian (3 for displacements; 10 = 3 + 4 + 3 when rotations and
    scales are predicted too). ``matmul_dtype``: the dtype of :meth:`forward`'s matrix products (None: the
    parameters'; ``torch.bfloat16``: mixed precision, see :class:`FusedMLP`); parameters stay float32."""

    def __init__(
        self,
        n_latent: int,
        n_moved: int,
        width: int = 256,
        depth: int = 3,
        x_freqs: int = 4,
        pose_freqs: int = 4,
        out_per_latent: int = 3,
        matmul_dtype: torch.dtype | None = None,
    ):
        super().__init__()
        self.matmul_dtype = matmul_dtype  # FusedMLP's compute dtype (None: the parameters'; see compute_dtype)
        if depth < 2:
            raise ValueError(f"ADE depth must be >= 2 (input and output layers), got {depth}")
        self.x_freqs, self.pose_freqs = x_freqs, pose_freqs
        self.n_moved, self.out_per_latent = n_moved, out_per_latent
        in_x = 3 * (1 + 2 * x_freqs)
        in_pose = n_latent * 9 * (1 + 2 * pose_freqs)
        self.first_x = nn.Linear(in_x, width)
        self.first_pose = nn.Linear(in_pose, width, bias=False)
        self.hidden = nn.ModuleList(nn.Linear(width, width) for _ in range(depth - 2))
        self.last = nn.Linear(width, n_moved * out_per_latent)
        for layer in [self.first_x, self.first_pose, *self.hidden, self.last]:
            nn.init.xavier_uniform_(layer.weight)
            if layer.bias is not None:
                nn.init.zeros_(layer.bias)
        # Xavier over the concatenated input: the two halves of the first layer share its fan-in
        with torch.no_grad():
            gain = math.sqrt(6.0 / (in_x + in_pose + width))
            self.first_x.weight.uniform_(-gain, gain)
            self.first_pose.weight.uniform_(-gain, gain)

    def encode_poses(self, c2w: Tensor) -> Tensor:
        """(L, 4, 4) latent poses of one view → (L·9·(1 + 2F),) float32 pose input."""
        return frequency_encoding(pose_features(c2w.to(torch.float32)), self.pose_freqs).reshape(-1)

    def forward(self, x: Tensor, pose_input: Tensor) -> Tensor:
        """``x`` (N, 3) centres (detached by the caller), ``pose_input`` from :meth:`encode_poses` →
        (N, n_moved, out_per_latent)."""
        params: list[Tensor] = [self.first_x.weight, self.first_x.bias + self.first_pose(pose_input)]  # per-view bias
        for layer in [*self.hidden, self.last]:
            params += [layer.weight, layer.bias]
        out = FusedMLP.apply(frequency_encoding(x, self.x_freqs), self.matmul_dtype, *params)
        return out.reshape(x.shape[0], self.n_moved, self.out_per_latent)

    def forward_reference(self, x: Tensor, pose_input: Tensor) -> Tensor:
        """:meth:`forward` through ``nn.Linear`` and ``torch.relu`` (the tests' reference)."""
        h = self.first_x(frequency_encoding(x, self.x_freqs)) + self.first_pose(pose_input)  # per-view bias
        h = torch.relu(h)
        for layer in self.hidden:
            h = torch.relu(layer(h))
        return self.last(h).reshape(x.shape[0], self.n_moved, self.out_per_latent)
