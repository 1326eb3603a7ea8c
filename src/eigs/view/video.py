"""Orbit videos of trained runs: each run rendered along a camera path around its scene (an orbit, or LLFF's
ellipse for a forward-facing capture: :func:`eigs.util.cameras.render_path`), several runs side by side with their
names above them, encoded as H.264 MP4 by the ffmpeg binary that the ``imageio-ffmpeg`` wheel ships.

Frames: (H, W, 3) uint8 RGB (grey scenes repeated to three channels). H.264 in yuv420p needs even sizes: a frame of
odd width or height is padded by one edge pixel. Panels: every run at its scene's resolution, left to right in the
order given, under a caption strip of :data:`CAPTION_PX` pixels.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.artifacts import run as run_folder
from eigs.errors import EigsError
from eigs.view.runs import RunInfo

CAPTION_PX = 16  # height of the caption strip above the panels (even, so it keeps the frame's height even)


@dataclass(frozen=True)
class VideoOptions:
    """Defaults of the ``video:`` config section and of ``eigs video``: ``frames`` along the path, played at ``fps``
    (60 at 20 fps: a three-second turn); ``table1_rows``: the Table I rows (eigs.tables.rows) whose runs the
    workflow shows side by side when the config names no ``runs``: the blurry input, the EDI input, the paper's EiGS,
    EiGS with the switches that pay, the upper bound."""

    frames: int = 60
    fps: int = 20
    table1_rows: tuple[str, ...] = ("3dgs", "edi-3dgs", "eigs", "eigs+", "oracle")


def even_frame(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 → the same frame padded by one edge row/column where H or W is odd (yuv420p needs even
    sizes)."""
    h, w = frame.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return np.ascontiguousarray(frame)
    return np.ascontiguousarray(np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge"))


def caption_strip(labels: Sequence[str], widths: Sequence[int]) -> np.ndarray:
    """(CAPTION_PX, sum(widths), 3) uint8: black, each label in white, left-aligned above its panel."""
    from PIL import Image, ImageDraw, ImageFont

    strip = Image.new("RGB", (int(sum(widths)), CAPTION_PX), (0, 0, 0))
    draw = ImageDraw.Draw(strip)
    font = ImageFont.load_default(size=CAPTION_PX - 4)
    x = 0
    for label, w in zip(labels, widths, strict=True):
        draw.text((x + 3, 1), label, fill=(255, 255, 255), font=font)
        x += w
    return np.asarray(strip, np.uint8)


def tile(panels: Sequence[np.ndarray], strip: np.ndarray | None) -> np.ndarray:
    """Panels (H_i, W_i, 3) uint8 side by side (shorter ones padded black at the bottom), under ``strip``."""
    h = max(p.shape[0] for p in panels)
    row = np.concatenate([np.pad(p, ((0, h - p.shape[0]), (0, 0), (0, 0))) for p in panels], axis=1)
    return row if strip is None else np.concatenate([strip, row], axis=0)


class RunRenderer:
    """A run's model on ``device``, rendering (H, W, 3) uint8 frames along ``frames`` cameras of its render path
    (the SfM folder's valid training cameras, latent 0, as ``eigs render --cameras orbit``)."""

    def __init__(self, run: RunInfo, frames: int, device: str = "auto") -> None:

        import torch

        from eigs.artifacts.field import read_field
        from eigs.artifacts.gaussians import read_gaussian_ply
        from eigs.artifacts.poses import read_poses
        from eigs.render.field import FieldTensors
        from eigs.scene import read_scene
        from eigs.train.gaussian.model import GaussianModel
        from eigs.util.cameras import render_path

        if run.scene is None:
            raise EigsError(run.path, "no scene file found for this run (pass --scene)")
        if not (run.sfm / "poses.h5").is_file():
            raise EigsError(run.sfm, "no poses.h5 (not an SfM folder of `eigs sfm`; pass --sfm)")
        self.label = run.label
        self.device = torch.device("cuda" if device == "cuda" or (device == "auto" and torch.cuda.is_available())
                                   else "cpu")  # fmt: skip
        scene = read_scene(run.scene, events=False)
        self.channels = scene.channels
        bg = scene.background if scene.background is not None else np.zeros(scene.channels)
        self.background = torch.tensor(np.asarray(bg, np.float32), device=self.device)
        poses = read_poses(run.sfm)
        self.width, self.height = int(poses.width), int(poses.height)
        valid = poses.valid[:, 0]
        if not valid.any():
            raise EigsError(run.sfm, "no training camera with a valid pose to place the camera path around")
        self.c2w, self.path_kind = render_path(poses.c2w[valid, 0], frames)
        self.K = np.asarray(poses.K, np.float64)
        self.field = None
        self.model = None
        if run.kind == "field":
            self.field = FieldTensors.from_arrays(read_field(run.model), self.device)
        else:
            try:
                sh_degree = int(run_folder.read_config(run.path)["train"]["sh_degree"])
            except (ValueError, KeyError, TypeError, OSError) as err:
                raise EigsError(run.path / run_folder.CONFIG, f"unreadable run config ({err})") from None
            self.model = GaussianModel.from_cloud(read_gaussian_ply(run.model), sh_degree, scene.channels,
                                                  self.device)  # fmt: skip

    def __len__(self) -> int:
        return len(self.c2w)

    def frame(self, i: int) -> np.ndarray:
        """(H, W, 3) uint8 render at the path's camera ``i``."""
        import torch

        from eigs.render.field import render_image
        from eigs.util.image import to_uint8

        c2w = torch.from_numpy(self.c2w[i])
        k = torch.from_numpy(self.K).float().to(self.device)
        with torch.no_grad():
            if self.field is not None:
                img = render_image(self.field, c2w, k, self.width, self.height, self.background)
            else:
                img, _, _ = self.model.render(c2w, k, self.width, self.height, self.background)
        out = to_uint8(img.clamp(0, 1).cpu().numpy())
        if out.ndim == 2:
            out = out[:, :, None]
        return np.repeat(out, 3, axis=2) if out.shape[2] == 1 else out[:, :, :3]


def orbit_frames(renderers: Sequence[RunRenderer], labels: bool = True) -> Iterator[np.ndarray]:
    """The video's frames: at each step of the path, every run's render side by side (even-sized uint8 RGB)."""
    n = len(renderers[0])
    strip = caption_strip([r.label for r in renderers], [r.width for r in renderers]) if labels else None
    for i in range(n):
        yield even_frame(tile([r.frame(i) for r in renderers], strip))


def encode_mp4(frames: Iterable[np.ndarray], path: str | os.PathLike, fps: float) -> int:
    """Encode (H, W, 3) uint8 frames of one even size as H.264 (yuv420p) MP4 at ``path``, atomically; returns the
    frame count. A frame of another size, an empty sequence or an ffmpeg failure is an :class:`EigsError`."""
    import imageio_ffmpeg

    from eigs.util.atomic import atomic_path

    path = Path(path)
    if path.suffix.lower() != ".mp4":
        raise EigsError(path, "the video is written as MP4: give an output path ending in .mp4")
    if not fps > 0:
        raise EigsError(path, f"fps must be positive, not {fps}")
    count = 0
    with atomic_path(path) as tmp:
        writer = None
        try:
            for frame in frames:
                frame = np.asarray(frame)
                if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
                    raise EigsError(path, f"frame {count}: expected (H, W, 3) uint8, got {frame.shape} {frame.dtype}")
                h, w = frame.shape[:2]
                if writer is None:
                    if h % 2 or w % 2:
                        raise EigsError(path, f"frame size {w}x{h}: H.264 (yuv420p) needs an even width and height")
                    size = (w, h)
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp), size, fps=fps, codec="libx264", pix_fmt_out="yuv420p", macro_block_size=1,
                        quality=None, output_params=["-crf", "23", "-preset", "medium", "-movflags", "+faststart"],
                    )  # fmt: skip
                    writer.send(None)
                elif (w, h) != size:
                    raise EigsError(path, f"frame {count} is {w}x{h}, the video {size[0]}x{size[1]}")
                writer.send(np.ascontiguousarray(frame))
                count += 1
            if writer is None:
                raise EigsError(path, "no frames to encode")
            writer.close()
            _check_written(tmp, path, count)
        except (OSError, RuntimeError) as err:
            lines = [s for s in str(err).strip().splitlines() if s.strip()]
            raise EigsError(path, f"ffmpeg failed: {lines[-1] if lines else type(err).__name__}") from None
        finally:
            if writer is not None:
                writer.close()
    return count


def _check_written(tmp: Path, path: str | os.PathLike, count: int) -> None:
    """The temporary video read back before it becomes ``path``: ffmpeg can exit without an error on a full disk
    and leave a file that no player opens (measured: "Invalid data found when processing input")."""
    from eigs.util.atomic import FULL_BELOW, disk_full_error, free_bytes

    try:
        frames = probe_mp4(tmp)["frames"]
    except EigsError:
        frames = None
    if frames == count:
        return
    free = free_bytes(tmp)
    if free is not None and free < FULL_BELOW:
        raise disk_full_error(path, free)
    raise EigsError(path, f"ffmpeg wrote {'an unreadable video' if frames is None else f'{frames} of {count} frames'}")


def probe_mp4(path: str | os.PathLike) -> dict:
    """``{"frames", "width", "height", "codec", "fps"}`` of a video, read back by the bundled ffmpeg (every frame is
    decoded, so the count is what a player shows). An unreadable file is an :class:`EigsError`."""
    import imageio_ffmpeg

    path = Path(path)
    if not path.is_file():
        raise EigsError(path, "no such video file")
    try:
        reader = imageio_ffmpeg.read_frames(str(path))
        meta = next(reader)
        reader.close()
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    except (OSError, RuntimeError, StopIteration) as err:
        lines = [s for s in str(err).strip().splitlines() if s.strip()]
        raise EigsError(path, f"not a readable video ({lines[-1] if lines else type(err).__name__})") from None
    w, h = meta["size"]
    return {"frames": int(frames), "width": int(w), "height": int(h), "codec": str(meta.get("codec", "")),
            "fps": float(meta.get("fps", 0.0))}  # fmt: skip
