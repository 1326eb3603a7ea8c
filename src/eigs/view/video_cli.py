"""``eigs video``: an orbit video (H.264 MP4) of trained runs. Each run is rendered along a camera path around its
scene (an orbit through the training cameras; LLFF's ellipse for a forward-facing capture), several runs side by side
under their names, at the scene's resolution; the encoder is the ffmpeg binary of the ``imageio-ffmpeg`` wheel.
Defaults: eigs.view.video.VideoOptions."""

from __future__ import annotations

import argparse

HELP = "render trained runs along an orbit, side by side, into an H.264 MP4 video"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", metavar="RUN_DIR", help="run folder(s) (model.ply or model.npz, config.json), "
                   "shown left to right")  # fmt: skip
    p.add_argument("-o", "--output", required=True, help="the video file (.mp4), written atomically")
    p.add_argument("--frames", type=int, default=None, help="frames along the path (default: VideoOptions, 60)")
    p.add_argument("--fps", type=float, default=None, help="frames per second (default: VideoOptions, 20)")
    p.add_argument("--scene", default=None, help="scene file of every run (default: from each run's config.json, "
                   "else RUN_DIR/../../scene.h5)")  # fmt: skip
    p.add_argument("--sfm", default=None, help="SfM folder of every run's cameras (default: from each run's "
                   "config.json, else RUN_DIR/../sfm)")  # fmt: skip
    p.add_argument("--no-labels", action="store_true", help="no caption strip with the runs' names")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))


def run(args: argparse.Namespace) -> int:
    import logging
    import time

    from eigs.errors import EigsError
    from eigs.view.runs import resolve_run
    from eigs.view.video import RunRenderer, VideoOptions, encode_mp4, orbit_frames, probe_mp4

    log = logging.getLogger("eigs.video")
    defaults = VideoOptions()
    frames = defaults.frames if args.frames is None else args.frames
    fps = defaults.fps if args.fps is None else args.fps
    if frames < 1:
        raise EigsError(None, f"--frames {frames}: needs at least one frame")
    if not fps > 0:
        raise EigsError(None, f"--fps {fps}: must be positive")
    if not args.output.lower().endswith(".mp4"):
        raise EigsError(args.output, "the video is written as MP4: give an output path ending in .mp4")
    renderers = [RunRenderer(resolve_run(r, sfm=args.sfm, scene=args.scene), frames, args.device) for r in args.runs]
    t0 = time.perf_counter()
    count = encode_mp4(orbit_frames(renderers, labels=not args.no_labels), args.output, fps)
    info = probe_mp4(args.output)
    if info["frames"] != count:
        raise EigsError(args.output, f"wrote {count} frames but the file decodes to {info['frames']}")
    log.info("wrote %s: %d frames (%s path), %dx%d, %s, %.1f s of video, %d runs, %.1f s", args.output, count,
             renderers[0].path_kind, info["width"], info["height"], info["codec"], count / fps, len(renderers),
             time.perf_counter() - t0)  # fmt: skip
    return 0
