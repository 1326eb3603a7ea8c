"""The viewer: a viser server (its web client ships inside the viser wheel and is served from this machine, so the
viewer works offline) showing the Gaussians of one or more runs of a scene, the scene's training and test cameras,
and a panel to switch runs (at the same camera) and to jump to a camera.

Runs are splat nodes of one scene; switching shows one and hides the others, so each browser keeps its camera.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from eigs.view.runs import RunInfo, Splats, ViewCamera, cloud_to_splats, scene_cameras, scene_centre, up_direction

if TYPE_CHECKING:
    import viser

log = logging.getLogger("eigs.view")

TRAIN_COLOUR = (40, 110, 230)
TEST_COLOUR = (235, 120, 20)
FREE = "(free)"


@dataclass
class ViewerContent:
    """Everything the server shows: ``runs`` with their splats (same order), the cameras of the first run's SfM
    folder, the image size, and the background colour (3,) in [0, 1]."""

    runs: list[RunInfo]
    splats: list[Splats]
    train: list[ViewCamera]
    test: list[ViewCamera]
    size: tuple[int, int]
    background: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    @property
    def cameras(self) -> dict[str, ViewCamera]:
        return {c.name: c for c in self.test + self.train}


def load_content(runs: Sequence[RunInfo]) -> ViewerContent:
    """Read the runs' Gaussians, the first run's cameras and its scene's background (black when the scene file is
    not found, as ``eigs render`` draws scenes without a background)."""
    from eigs.artifacts.gaussians import read_gaussian_ply

    splats = []
    for run in runs:
        splats.append(cloud_to_splats(read_gaussian_ply(run.model)))
        log.info("%s: %d Gaussians from %s", run.label, len(splats[-1]), run.model)
    train, test, size = scene_cameras(runs[0].sfm, scene_centre(splats[0]))
    background = np.zeros(3)
    if runs[0].scene is not None:
        from eigs.scene import read_scene

        scene = read_scene(runs[0].scene, events=False, binned=False)
        if scene.background is not None:
            bg = np.asarray(scene.background, np.float64).reshape(-1)
            background = np.repeat(bg, 3)[:3] if bg.size == 1 else bg[:3]
    else:
        log.warning("no scene file found for %s: black background", runs[0].path)
    return ViewerContent(list(runs), splats, train, test, size, background, up_direction(train or test))


def _set_client_camera(client: viser.ClientHandle, cam: ViewCamera) -> None:
    """Move one browser's camera to ``cam`` (position, orientation through look-at and up, vertical fov)."""
    with client.atomic():
        client.camera.fov = cam.fov_y
        client.camera.position = cam.position
        client.camera.look_at = cam.look_at
        client.camera.up_direction = cam.up


class Viewer:
    """A running viser server with ``content``; :meth:`stop` shuts it down (idempotent)."""

    def __init__(self, content: ViewerContent, *, host: str = "127.0.0.1", port: int = 8080,
                 initial: ViewCamera | None = None, frustum_scale: float | None = None) -> None:  # fmt: skip
        import viser

        self.content = content
        self._stopped = False
        self._lock = threading.Lock()
        self.server = viser.ViserServer(host=host, port=port, label="eigs view", verbose=False)
        server = self.server
        server.gui.configure_theme(show_share_button=False, show_logo=False)
        server.scene.set_up_direction(tuple(float(x) for x in content.up))
        bg = np.broadcast_to(np.clip(content.background, 0, 1) * 255, (8, 8, 3)).astype(np.uint8)
        server.scene.set_background_image(bg, format="png")

        self.splat_nodes = [
            server.scene.add_gaussian_splats(f"/runs/{i}", centers=s.centers, covariances=s.covariances,
                                             rgbs=s.rgbs, opacities=s.opacities, visible=i == 0)  # fmt: skip
            for i, s in enumerate(content.splats)
        ]
        scale = frustum_scale if frustum_scale is not None else self._frustum_scale()
        self.frustums: list[Any] = []
        for cams, colour, group in ((content.train, TRAIN_COLOUR, "train"), (content.test, TEST_COLOUR, "test")):
            for k, cam in enumerate(cams):
                node = server.scene.add_camera_frustum(
                    f"/cameras/{group}/{k}", fov=cam.fov_y, aspect=cam.aspect, scale=scale, thickness=1.5,
                    thickness_units="screen", color=colour, wxyz=cam.wxyz, position=cam.position,
                )  # fmt: skip
                node.on_click(self._goto_on_click(cam))
                self.frustums.append(node)

        labels = [r.label for r in content.runs]
        self.run_menu = server.gui.add_dropdown("Run", labels, initial_value=labels[0],
                                                hint="the run whose Gaussians are shown; the camera stays")  # fmt: skip
        self.run_menu.on_update(lambda _: self.show_run(labels.index(self.run_menu.value)))
        names = [FREE, *content.cameras]
        self.camera_menu = server.gui.add_dropdown(
            "Camera", names, initial_value=FREE, hint="jump to a test (orange) or training (blue) camera"
        )
        self.camera_menu.on_update(self._on_camera_menu)
        self.show_cameras = server.gui.add_checkbox("Show cameras", True)
        self.show_cameras.on_update(lambda _: self._set_frustums_visible(self.show_cameras.value))
        w, h = content.size
        server.gui.add_markdown(f"{len(content.test)} test, {len(content.train)} training cameras ({w}×{h}); "
                                "click a frustum to look through it.")  # fmt: skip

        start = initial or (content.test[0] if content.test else content.train[0] if content.train else None)
        if start is not None:
            ic = server.initial_camera
            ic.fov = start.fov_y
            ic.position = start.position
            ic.look_at = start.look_at
            ic.up = start.up

    @property
    def port(self) -> int:
        return self.server.get_port()

    def url(self) -> str:
        host = self.server.get_host()
        host = "127.0.0.1" if host in ("0.0.0.0", "") else host
        return f"http://{host}:{self.port}/"

    def _frustum_scale(self) -> float:
        """A tenth of the median distance between neighbouring cameras, at most a twentieth of the scene's size."""
        cams = self.content.train + self.content.test
        pts = np.concatenate([s.centers for s in self.content.splats[:1]])
        extent = float(np.linalg.norm(np.percentile(pts, 95, axis=0) - np.percentile(pts, 5, axis=0))) or 1.0
        if len(cams) < 2:
            return 0.05 * extent
        pos = np.stack([c.position for c in cams])
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        d[d == 0] = np.inf
        nn = float(np.median(d.min(axis=1)))
        return float(min(0.3 * nn if np.isfinite(nn) else np.inf, 0.05 * extent))

    def show_run(self, index: int) -> None:
        """Show run ``index``'s Gaussians and hide the others (every browser keeps its camera)."""
        with self.server.atomic():
            for i, node in enumerate(self.splat_nodes):
                node.visible = i == index
        log.info("showing %s", self.content.runs[index].label)

    def _set_frustums_visible(self, visible: bool) -> None:
        with self.server.atomic():
            for node in self.frustums:
                node.visible = visible

    def _goto_on_click(self, cam: ViewCamera) -> Any:
        def cb(event: Any) -> None:
            _set_client_camera(event.client, cam)

        return cb

    def _on_camera_menu(self, event: Any) -> None:
        """Move the browser that picked a camera there, then set the menu back to (free), so picking the same
        camera again after orbiting away works."""
        cam = self.content.cameras.get(self.camera_menu.value)
        if cam is None or event.client is None:
            return
        _set_client_camera(event.client, cam)
        self.camera_menu.value = FREE

    def stop(self) -> None:
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
        self.server.stop()
