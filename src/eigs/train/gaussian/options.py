"""Options of the Gaussian methods (no torch): one frozen dataclass per method class, every default and check.

A method's recipe (:mod:`eigs.train.catalog`) overrides some defaults of its class's options (``eigs-b`` is
:class:`MultiRenderOptions` with ``consistency: false``); a run's ``method_options`` go over the recipe.
"""

from __future__ import annotations

from dataclasses import dataclass

from eigs.util.options import Options

PRECISIONS = ("auto", "float32", "bfloat16")  # the ADE's matmul dtypes (eigs.train.gaussian.ade.compute_dtype)
MODES = ("linear", "cubic", "bezier")  # trajectory curves (eigs.train.gaussian.trajectory.curve_weights)


def control_problem(mode: str, n_control: int) -> str | None:
    """Why ``n_control`` control twists do not fit a trajectory curve ``mode`` (None when they do)."""
    if mode not in MODES:
        return f"trajectory mode must be one of {', '.join(MODES)}, got {mode!r}"
    if mode == "linear" and n_control != 2:
        return "a linear trajectory has 2 control twists"
    if mode == "cubic" and n_control != 4:
        return "a cubic B-spline trajectory has 4 control twists"
    if mode == "bezier" and n_control < 2:
        return "a Bézier trajectory has at least 2 control twists"
    return None


@dataclass(frozen=True)
class MultiRenderOptions(Options):
    """The N+1-render methods (:mod:`eigs.train.gaussian.deblur`: EiGS, its ablations, Deblurring-GS(+), E2GS)."""

    ade: bool = True  # per-Gaussian displacements from the ADE network (False: render the latent poses P_k)
    shape: bool = False  # ADE also predicts rotation and scale changes (Deblurring-GS+)
    event_loss: str = "eigs"  # "eigs" (Eq. 9–10), "e2nerf" (E²NeRF/E2GS pairwise) or "none"
    consistency: bool = True  # motion-consistency loss (Eq. 3–6)
    lambda_p: float = 1e-2  # λ_p, scale of the predicted displacements (and rotation/scale changes)
    lambda_event: float = 0.005
    # beyond the paper: sensor-noise-aware event loss (eigs.losses.events.event_integration_loss): errors up to
    # event_deadzone + event_mismatch·|E| events are free (count quantisation, threshold mismatch, refractory period)
    event_deadzone: float = 0.0
    event_mismatch: float = 0.0
    lambda_consis: float = 1.0
    huber_delta: float = 0.1  # Huber threshold δ of Eq. 6 (eigs.losses.consistency.DEFAULT_DELTA)
    consis_reg: float = 1e-8  # λ_reg of Eq. 5 (eigs.losses.consistency.DEFAULT_REG)
    grad_through_fit: bool = True
    width: int = 256
    depth: int = 3
    x_freqs: int = 4
    pose_freqs: int = 4
    lr_ade: float = 1e-3
    # dtype of the ADE's matrix products: "float32", "bfloat16" (mixed precision: float32 parameters, Adam and
    # outputs; bfloat16 products and kept activations) or "auto" (bfloat16 where the hardware multiplies it
    # natively: AMX / AVX512-BF16 CPUs, bf16 GPUs; float32 elsewhere). docs/training.md "ADE precision"
    ade_precision: str = "auto"
    pose_prior: bool = False  # beyond the paper: ADE predicts the residual to the displacement the latent poses imply
    subframes: int = 1  # beyond the paper: renders per latent interval (> 1 adds interpolated displacements)
    blur_weights: str = "uniform"  # "uniform" (Eq. 2) or "trapezoid" (the exposure integral by the trapezoid rule)
    # beyond the paper: "blurry" (Eq. 8) or "discrete" (the blurry frame corrected for the N+1-sample average by the
    # events: the average of EDI's latent frames with the same weights, which equals the continuous exposure
    # average of the frame; docs/methods.md)
    blur_target: str = "blurry"
    # the discrete target keeps the blurry frame where it is darker than this (linear intensity, [0, 1]); the ratio
    # test ([2/3, 3/2]) applies everywhere. 0.02 (5 of 255): the value the ledgers were made with
    discrete_floor: float = 0.02
    # beyond the paper: L1 between each latent render k and EDI's latent frame k, with this weight (0: off); the
    # event-integration loss constrains only differences of consecutive renders, this ties each render to the frame
    # the events and the blurry frame imply for its time (no extra renders)
    latent_weight: float = 0.0
    # beyond the paper: the latent term as edi-3dgs's photometric loss, (1 − lambda_dssim)·L1 + lambda_dssim·D-SSIM
    # over the latent renders, instead of L1 alone (the D-SSIM asks for local contrast, which L1 on dark frames barely
    # weighs; issue 43, docs/results.md "Why eigs+ renders smooth")
    latent_dssim: bool = False
    # beyond the paper: the latent term's weight instead of latent_weight on a dark scene, one whose blurry frames'
    # texture SSIM cannot see (eigs.metrics.texture: median local variance below DARK_TEXTURE × C2), where the blur
    # term does not ask for the texture and only the latent term can (issue 43; 0: latent_weight on every scene)
    latent_weight_dark: float = 0.0
    ade_zero_last: bool = False  # beyond the paper: the ADE's last layer starts at zero (no displacement at step 0)
    sharp_one_render: bool = True  # views EDI marks sharp (too few events) use one render and the photometric loss

    def problems(self) -> list[str]:
        checks = [
            (self.event_loss in ("eigs", "e2nerf", "none"),
             f"event_loss must be eigs, e2nerf or none, got {self.event_loss!r}"),
            (self.ade or not (self.consistency or self.shape or self.pose_prior or self.subframes != 1),
             "consistency, shape, pose_prior, subframes need the ADE (ade: true)"),
            (self.ade_precision in PRECISIONS, f"ade_precision must be one of {', '.join(PRECISIONS)}"),
            (min(self.event_deadzone, self.event_mismatch) >= 0, "event_deadzone and event_mismatch must be >= 0"),
            (self.subframes >= 1 and self.blur_weights in ("uniform", "trapezoid"),
             "subframes must be >= 1 and blur_weights uniform or trapezoid"),
            (self.blur_target in ("blurry", "discrete") and (self.blur_target == "blurry" or self.subframes == 1),
             "blur_target must be blurry or discrete (discrete needs subframes 1)"),
            (min(self.latent_weight, self.latent_weight_dark) >= 0,
             "latent_weight and latent_weight_dark must be >= 0"),
            (0 <= self.discrete_floor < 1, "discrete_floor must lie in [0, 1)"),
        ]  # fmt: skip
        return [msg for ok, msg in checks if not ok]


@dataclass(frozen=True)
class TrajectoryOptions(Options):
    """The camera-trajectory methods (:mod:`eigs.train.gaussian.camera_motion`: BAD-Gaussians, BeSplat,
    EvaGaussians)."""

    mode: str = "linear"  # trajectory curve: linear, cubic (B-spline) or bezier
    n_control: int = 2  # control twists of the curve (linear 2, cubic 4, Bézier ≥ 2)
    n_virtual: int = 10  # virtual cameras rendered per step (BAD-Gaussians: 10)
    init: str = "latent"  # "latent" (fit to the SfM latent poses) or "reference" (zero motion + 1e-5 noise)
    lr_pose: float = 1e-3  # Adam learning rate of the control twists (rad and scene units per step)
    event_loss: str = "none"  # "none", "eigs" (Eq. 9–10, L1 of the integral) or "normalized" (BeSplat)
    lambda_event: float = 0.0
    lambda_blur: float = 1.0
    sharp_one_render: bool = True  # views EDI marks sharp (too few events) use one render at P_ref, blur loss only

    def problems(self) -> list[str]:
        out = [p for p in (control_problem(self.mode, self.n_control),) if p]
        if self.n_virtual < 2 or self.init not in ("latent", "reference"):
            out.append("n_virtual must be >= 2 and init latent or reference")
        if self.event_loss not in ("none", "eigs", "normalized"):
            out.append(f"event_loss must be none, eigs or normalized, got {self.event_loss!r}")
        return out
