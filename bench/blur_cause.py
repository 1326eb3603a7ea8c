"""What keeps the multi-render methods' renders smoother than `edi-3dgs`'s (issue 43, part 4): one scene's runs, each
with one thing changed, scored for sharpness beside PSNR and LPIPS.

At 346×260 `eigs+`'s novel views keep a tenth of the ground truth's power above 0.25 cycles/pixel where `edi-3dgs`
keeps a third (docs/results.md). The candidates, one variant each, all on the scene's own EDI, init and budgets:

- ``eigs+``, ``edi-3dgs``: the runs as the config defines them (SfM poses);
- ``eigs+-gt``, ``edi-3dgs-gt``: the scene's ground-truth latent poses instead of SfM's (``eigs sfm --mode given``;
  init from those poses, evaluated at their test cameras): is it the motion the renders are moved by? The EiGS blur
  average moves its N + 1 renders by the latent poses' relative motion (plus the ADE's residual); where that motion
  is off by a fraction of the blur length, an average of sharp renders cannot match the frame and a smoother scene
  fits it better. With ground-truth poses the renders are registered to their ground truth, so the coherence reads.

Then, each on ``eigs+-gt`` (ground-truth poses, so that neither the poses nor the test cameras' registration enter):

- ``-norms``: densification by the sum of the renders' gradient norms (``grow_grad2d_renders: norm_sum``): is it
  the Gaussians the blur average does not grow?
- ``-noevent``: no event-integration loss: is it the events (noisy at the preset's light level)?
- ``-latent2``: ``latent_weight`` 2 instead of 0.5: is it the weight of the sharp EDI frames against the blur?
  ``-latent4``, ``-latent8``: further up that axis; ``-latent2-dssim``, ``-latent4-dssim``: the latent term as
  ``edi-3dgs``'s photometric loss (L1 + D-SSIM, ``latent_dssim``), the loss the sharpest run trains with;
- ``-floor0``: the discrete blur target in the dark pixels too (``discrete_floor`` 0 instead of 0.02): at the
  preset's light level 31 % of d346-chair's pixels are darker than 0.02 and keep the blurry frame as target, which
  an average of N + 1 sharp renders cannot match (the discrete average is not the exposure integral), and an L1
  loss pulls as hard on a dark pixel as on a bright one;
- ``-noade``: no ADE (the renders at the latent poses; without the ADE there is no residual to regularise, so no
  consistency loss either): is it the ADE's displacements?

``oracle-gt`` and ``oracle-gt-3dgs``: the oracle (sharp ground-truth frames) on ground-truth poses at the config's
budget and at the 3DGS reference schedule: the ceiling at the scene's size, beside which the other runs stand.

``eigs+-latent2`` and ``eigs+-latent4-dssim`` change the latent term of the pipeline's run (SfM poses): does what
moves the ground-truth-pose run move the run a user gets?

Each variant is trained and evaluated by the CLI (``eigs train``, ``eigs evaluate`` with the scene's flags from the
config) into ``--work`` (default ``results/bench/blur_cause/<scene>``; a finished variant is not retrained). Reported:
novel-view PSNR, SSIM, LPIPS, sharpness (``eigs.metrics.sharpness``: the high-frequency power ratio against the
ground truth, 1 = as sharp), final Gaussians, the displacement error of the latent motion (``motion`` in
metrics.json; 0 exact, 1 as wrong as none) and the training time.

Run: ``.venv/bin/python bench/blur_cause.py --results results/d346-chair --config config/davis346.yaml
[--variants eigs+ eigs+-gt ...] [--threads 1] [--tag T] [--out DIR]``; the section is named
``blur-cause-<scene>`` (``blur-cause-<scene>-<T>`` with ``--tag``, so that a second set of variants keeps the first's
section).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, timed, write_section  # noqa: E402

# name → (the config's run it changes, options merged into that run's options, poses: "sfm" or "given")
VARIANTS: dict[str, tuple[str, dict, str]] = {
    "edi-3dgs": ("edi-3dgs", {}, "sfm"),
    "eigs+": ("eigs+", {}, "sfm"),
    "edi-3dgs-gt": ("edi-3dgs", {}, "given"),
    "eigs+-gt": ("eigs+", {}, "given"),
    "eigs+-gt-norms": ("eigs+", {"grow_grad2d_renders": "norm_sum"}, "given"),
    "eigs+-gt-noevent": ("eigs+", {"method_options": {"event_loss": "none"}}, "given"),
    "eigs+-gt-latent2": ("eigs+", {"method_options": {"latent_weight": 2.0}}, "given"),
    "eigs+-gt-latent4": ("eigs+", {"method_options": {"latent_weight": 4.0}}, "given"),
    "eigs+-gt-latent8": ("eigs+", {"method_options": {"latent_weight": 8.0}}, "given"),
    "eigs+-gt-latent2-dssim": ("eigs+", {"method_options": {"latent_weight": 2.0, "latent_dssim": True}}, "given"),
    "eigs+-gt-latent4-dssim": ("eigs+", {"method_options": {"latent_weight": 4.0, "latent_dssim": True}}, "given"),
    "eigs+-latent2": ("eigs+", {"method_options": {"latent_weight": 2.0}}, "sfm"),
    "eigs+-latent4-dssim": ("eigs+", {"method_options": {"latent_weight": 4.0, "latent_dssim": True}}, "sfm"),
    "oracle-gt": ("oracle", {}, "given"),
    # the 3DGS reference schedule (Kerbl et al. 2023, train.py / arguments): 30k steps, SH degree 3, densification
    # every 100 steps from 500 to 15k at 2e-4, opacity reset every 3000, prune below 0.005, position lr 1.6e-4
    # decaying 100× (the trainer multiplies it by the scene extent, as 3DGS does)
    "oracle-gt-3dgs": ("oracle", {"steps": 30000, "sh_degree": 3, "refine_start": 500, "refine_stop_frac": 0.5,
                                  "grow_grad2d": 2e-4, "reset_every": 3000, "prune_opacity": 0.005,
                                  "lr_means": 1.6e-4, "lr_means_final": 1.6e-6, "eval_every": 2500,
                                  "checkpoint_every": 5000}, "given"),
    "eigs+-gt-floor0": ("eigs+", {"method_options": {"discrete_floor": 0.0}}, "given"),
    "eigs+-gt-noade": ("eigs+", {"method_options": {"ade": False, "pose_prior": False, "consistency": False}},
                       "given"),
}


def run_options(spec: dict, patch: dict) -> dict:
    """The run's ``--config`` object: method and options, ``patch`` merged (``method_options`` key by key)."""
    opts = copy.deepcopy(spec.get("options", {}))
    for key, value in patch.items():
        if key == "method_options":
            opts["method_options"] = {**opts.get("method_options", {}), **value}
        else:
            opts[key] = value
    return {"method": spec["method"], **opts}


def given_upstream(results: Path, bins: int, work: Path, threads: int) -> tuple[Path, Path]:
    """SfM folder and init of the scene's ground-truth latent poses (``eigs sfm --mode given``), made once."""
    sfm, init = work / "sfm-given", work / "init-given.ply"
    if not init.is_file():
        b = results / f"b{bins}"
        timed(["eigs", "sfm", str(results / "scene.h5"), str(b / "edi.h5"), "--latent-dir", str(b / "latent"), "-o",
            str(sfm), "--mode", "given", "--threads", str(threads)], work / "sfm-given.log")  # fmt: skip
        timed(["eigs", "init", str(sfm), "-o", str(init)], work / "init-given.log")
    return sfm, init


def render_coherence(renders: Path) -> float | None:
    """Mean high-frequency coherence (``eigs.metrics.sharpness.hf_coherence``) of the novel-view renders in an
    evaluation's ``renders/`` against its ``gt_novel/`` (None without them)."""
    import numpy as np

    from eigs.metrics.image import read_image
    from eigs.metrics.sharpness import hf_coherence

    pairs = [(f, renders / "gt_novel" / f.name) for f in sorted((renders / "novel").glob("*.png"))]
    got = [hf_coherence(read_image(a), read_image(b)) for a, b in pairs if b.is_file()]
    return float(np.mean(got)) if got else None


def measure(name: str, results: Path, cfg: dict, bins: int, work: Path, threads: int) -> dict:
    from eigs import plan

    base, patch, poses = VARIANTS[name]
    b = results / f"b{bins}"
    sfm, init = (b / "sfm", b / "init.ply") if poses == "sfm" else given_upstream(results, bins, work, threads)
    run_dir, metrics = work / name, work / "eval" / name / "metrics.json"  # beside it: per_image.csv, renders/
    options = run_options(cfg["runs"][base], patch)
    if not metrics.is_file():
        timed(["eigs", "train", str(results / "scene.h5"), str(b / "edi.h5"), str(sfm), str(init), "-o", str(run_dir),
            "--config", json.dumps(options), "--threads", str(threads)], work / f"{name}.train.log")  # fmt: skip
        flags = plan.evaluate_flags(cfg, results.name)
        metrics.parent.mkdir(parents=True, exist_ok=True)
        timed(["eigs", "evaluate", str(run_dir), str(results / "scene.h5"), str(sfm), "-o", str(metrics), *flags,
            "--threads", str(threads)], work / f"{name}.evaluate.log")  # fmt: skip
    m = json.loads(metrics.read_text())
    novel = m["metrics"]["novel"]
    coherence = render_coherence(metrics.parent / "renders")
    motion = (m.get("motion") or {}).get("displacement_relative_error")
    return {"base": base, "options": options, "poses": poses, "psnr": novel["psnr"], "ssim": novel["ssim_3dgs"],
            "lpips": novel["lpips_alex"], "sharpness": novel.get("sharpness"), "coherence": coherence,
            "gaussians": m["n_gaussians"],
            "motion_error": motion, "train_seconds": m["train_seconds"]}  # fmt: skip


def target_sharpness(results: Path, bins: int) -> dict:
    """Sharpness of what the methods train on, against each blur view's ground truth (mean over the blur views):
    the blurry frame, and EDI's latent frame at the ground truth's time (the nearest latent time)."""
    import numpy as np

    from eigs.artifacts.edi import read_edi
    from eigs.metrics.sharpness import hf_scores
    from eigs.scene.file import read_scene

    scene = read_scene(results / "scene.h5", events=False)
    edi = read_edi(results / f"b{bins}" / "edi.h5")
    sharp, blurry = scene.sharp, scene.frames.blurry
    got: dict[str, list[float]] = {"blurry": [], "latent": [], "blurry_coherence": [], "latent_coherence": [],
                                   "blur_extent_px": []}
    for i in np.nonzero(sharp.kind == 0)[0]:
        v = int(sharp.view[i])
        k = int(np.argmin(np.abs(edi.timestamps_us[v] - sharp.t_us[i])))
        latent = np.clip(np.round(edi.latent[v, k] * 255.0), 0, 255).astype(np.uint8)
        for key, img in (("blurry", blurry[v]), ("latent", latent)):
            ratio, coherence = hf_scores(img, sharp.images[i])
            got[key].append(ratio)
            got[f"{key}_coherence"].append(coherence)
        got["blur_extent_px"].append(float(edi.blur_extent_px[v]))
    return {k: float(np.mean(v)) for k, v in got.items()} | {"views": len(got["blurry"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", type=Path, required=True, help="a scene's results folder (results/<scene>)")
    ap.add_argument("--config", type=Path, required=True, help="the config whose runs: entries are changed")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--bins", type=int, default=4)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--work", type=Path, default=None, help="where the runs go (default results/bench/blur_cause/…)")
    ap.add_argument("--tag", default="", help="section blur-cause-<scene>-<tag> (default: blur-cause-<scene>)")
    add_out_argument(ap)
    args = ap.parse_args()
    cfg = yaml.safe_load(args.config.read_text())
    scene = args.results.name
    work = args.work or Path("results/bench/blur_cause") / scene
    work.mkdir(parents=True, exist_ok=True)
    got = {}
    for name in args.variants:
        got[name] = measure(name, args.results, cfg, args.bins, work, args.threads)
        print(name, {k: v for k, v in got[name].items() if k != "options"}, flush=True)

    targets = target_sharpness(args.results, args.bins)
    print("training targets", targets, flush=True)

    def fmt(v: float | None, digits: int) -> str:
        return "–" if v is None else f"{v:.{digits}f}"

    rows = [[f"`{n}`", f"`{g['base']}`", g["poses"], fmt(g["psnr"], 2), fmt(g["ssim"], 4), fmt(g["lpips"], 3),
             fmt(g["sharpness"], 2), fmt(g["coherence"], 2), g["gaussians"], fmt(g["motion_error"], 3),
             fmt(g["train_seconds"], 0)] for n, g in got.items()]  # fmt: skip
    body = (
        f"Scene `{scene}` (B = {args.bins}, {args.threads} thread(s) a run, each run's own budget; "
        f"`bench/blur_cause.py`, config `{args.config}`). One change a row against its base run; 'poses': SfM's "
        "(the pipeline's) or the scene's ground truth (`eigs sfm --mode given`, scored at its own test cameras). "
        "Novel views: PSNR (dB), SSIM, LPIPS (alex), sharpness (high-frequency power against the ground truth's, "
        "1 = as sharp), coherence (the ground truth's high-frequency detail reproduced, `hf_coherence`: noise does "
        "not raise it); Gaussians at the end; motion error: the displacement error of the latent motion (0 exact, "
        "1 as wrong as none); training seconds.\n\n"
        + table(["variant", "base", "poses", "PSNR", "SSIM", "LPIPS", "sharpness", "coherence", "Gaussians",
                 "motion err", "train s"], rows)  # fmt: skip
        + f"\n\nWhat the runs train on, the same sharpness against each blur view's ground truth (mean of "
        f"{targets['views']} views): the blurry frame {targets['blurry']:.3f} (coherence "
        f"{targets['blurry_coherence']:.2f}); EDI's latent frame at the ground truth's time {targets['latent']:.3f} "
        f"(coherence {targets['latent_coherence']:.2f}; power above the coherence's square is power the ground "
        f"truth does not explain: noise); EDI's estimated blur extent {targets['blur_extent_px']:.1f} px."
    )
    suffix = f"-{args.tag}" if args.tag else ""
    title = f"What keeps the renders smooth: {scene} (issue 43{', ' + args.tag if args.tag else ''})"
    write_section(f"blur-cause-{scene}{suffix}", title, body,
                  data={"variants": got, "targets": targets}, out=args.out)


if __name__ == "__main__":
    main()
