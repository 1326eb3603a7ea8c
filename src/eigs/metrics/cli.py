"""``eigs metric``: image-quality metrics of users' own image files or directories."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = (
    "image-quality metric (psnr, ssim, lpips, sharpness, coherence, brisque) of an image or a directory of images"
)
METRICS = ("psnr", "ssim", "lpips", "sharpness", "coherence", "brisque")
FULL_REFERENCE = ("psnr", "ssim", "lpips", "sharpness", "coherence")
BRISQUE_KINDS = {"original": "brisque", "opencv": "brisque_opencv"}  # variant → resource kind


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = (
        "Images are read as 8-bit (16-bit files are rounded to 8 bits; alpha is dropped). With directories, "
        "images are paired by file name (or by stem when the extensions differ), a CSV 'image,<metric>' is "
        "printed, and the last line is the mean. With single files the only line is the value."
    )
    parser.add_argument("metric", choices=METRICS, help="which metric")
    parser.add_argument("image", type=Path, help="image file, or directory of images")
    parser.add_argument("reference", type=Path, nargs="?", help="reference file or directory (not for brisque)")
    parser.add_argument(
        "--mode",
        choices=("3dgs", "skimage-gaussian", "deblurnerf"),
        default="3dgs",
        help="SSIM lineage (default: 3dgs; see docs/metrics.md)",
    )
    parser.add_argument("--net", choices=("alex", "vgg"), default="alex", help="LPIPS network (default: alex)")
    from eigs.metrics.noreference import DEFAULT_VARIANT, VARIANTS

    parser.add_argument(
        "--brisque-variant",
        choices=VARIANTS,
        default=DEFAULT_VARIANT,
        help=f"BRISQUE: the original algorithm and LIVE model, or the OpenCV-feature variant (default: "
        f"{DEFAULT_VARIANT}; see docs/metrics.md)",
    )
    parser.add_argument(
        "--resources",
        type=Path,
        default=None,
        metavar="DIR",
        help="model files (default: the repository's resources/); made there on first use like `eigs resources`",
    )
    parser.add_argument("--csv", type=Path, default=None, metavar="FILE", help="also write the per-image CSV here")


def _pairs(image: Path, reference: Path | None) -> list[tuple[str, Path, Path | None]]:
    """(name, image path, reference path) for a file or a directory (paired by name, then by stem)."""
    from eigs.errors import EigsError
    from eigs.metrics.image import IMAGE_SUFFIXES

    if not image.exists():
        raise EigsError(image, "no such file or directory")
    if reference is not None and not reference.exists():
        raise EigsError(reference, "no such file or directory")
    if not image.is_dir():
        if reference is not None and reference.is_dir():
            raise EigsError(reference, "is a directory but the image is a file; give two files or two directories")
        return [(image.name, image, reference)]
    if reference is not None and not reference.is_dir():
        raise EigsError(reference, "is a file but the image is a directory; give two files or two directories")
    images = sorted(p for p in image.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise EigsError(image, f"no images ({', '.join(IMAGE_SUFFIXES)}) in this directory")
    if reference is None:
        return [(p.name, p, None) for p in images]
    refs = {p.name: p for p in reference.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES}
    by_stem: dict[str, list[Path]] = {}
    for p in refs.values():
        by_stem.setdefault(p.stem, []).append(p)
    out, missing = [], []
    for p in images:
        ref = refs.get(p.name)
        if ref is None and len(by_stem.get(p.stem, [])) == 1:
            ref = by_stem[p.stem][0]
        if ref is None:
            missing.append(p.name)
        else:
            out.append((p.name, p, ref))
    if missing:
        shown = ", ".join(missing[:5]) + (" …" if len(missing) > 5 else "")
        raise EigsError(reference, f"no reference image for {len(missing)} image(s): {shown}")
    return out


def _fmt(v: float) -> str:
    return f"{v:.8g}"


def run(args: argparse.Namespace) -> int:
    import math

    from eigs.errors import EigsError
    from eigs.metrics.image import read_image
    from eigs.util.atomic import atomic_path
    from eigs.util.progress import progress

    if args.metric in FULL_REFERENCE and args.reference is None:
        raise EigsError(None, f"{args.metric} needs a REFERENCE image or directory")
    if args.metric == "brisque" and args.reference is not None:
        raise EigsError(args.reference, "brisque is a no-reference metric; give only IMAGE")
    pairs = _pairs(args.image, args.reference)
    if args.metric in ("lpips", "brisque"):  # model files: made on first use (pinned, checksummed)
        from eigs.metrics.resources import ensure

        ensure("lpips" if args.metric == "lpips" else BRISQUE_KINDS[args.brisque_variant], args.resources)

    if args.metric == "psnr":
        from eigs.metrics.pixel import psnr as fn

        def score(a, b):
            return fn(a, b)
    elif args.metric == "ssim":
        from eigs.metrics.pixel import ssim

        def score(a, b):
            return ssim(a, b, mode=args.mode)
    elif args.metric == "lpips":
        from eigs.metrics.perceptual import lpips

        def score(a, b):
            return lpips(a, b, net=args.net, resources_dir=args.resources)
    elif args.metric == "sharpness":  # the high-frequency power ratio of the image against the reference
        from eigs.metrics.sharpness import hf_ratio

        def score(a, b):
            return hf_ratio(a, b)
    elif args.metric == "coherence":  # the reference's high-frequency detail the image reproduces
        from eigs.metrics.sharpness import hf_coherence

        def score(a, b):
            return hf_coherence(a, b)
    else:
        from eigs.metrics.noreference import brisque

        def score(a, _b):
            return brisque(a, resources_dir=args.resources, variant=args.brisque_variant)

    rows: list[tuple[str, float]] = []
    items = progress(pairs, desc=args.metric, unit="img") if len(pairs) > 1 else pairs
    for name, img_path, ref_path in items:
        img = read_image(img_path)
        ref = read_image(ref_path) if ref_path is not None else None
        try:
            value = score(img, ref)
        except EigsError as err:
            if err.path is None:  # name the file the problem belongs to
                raise EigsError(img_path, err.problem) from err
            raise
        rows.append((name, value))

    column = args.metric if args.metric != "ssim" else f"ssim_{args.mode}"
    if args.metric == "lpips":
        column = f"lpips_{args.net}"
    if args.metric == "brisque" and args.brisque_variant != "original":
        column = f"brisque_{args.brisque_variant}"
    lines = [f"image,{column}"] + [f"{name},{_fmt(v)}" for name, v in rows]
    if args.csv is not None:
        with atomic_path(args.csv) as tmp:
            tmp.write_text("\n".join(lines) + "\n")
    if args.image.is_dir():
        values = [v for _, v in rows]
        mean = math.inf if any(math.isinf(v) for v in values) else math.fsum(values) / len(values)
        print("\n".join(lines))
        print(_fmt(mean))
    else:
        print(_fmt(rows[0][1]))
    return 0
