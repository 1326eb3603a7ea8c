"""docs/own-data.md: its command block runs as written, in order, on the first views of the ECD sample of
../shared/data/real (skips locally without it, fails under CI=true), in a scratch directory laid out like the
repository (workflow, rules, config and the venv linked); the last command, the viewer, is started, must print its
address and is stopped."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eigs.view.video import probe_mp4

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "own-data.md"


def doc_commands(marker: str = "commands") -> list[str]:
    """The lines of the doc's bash block marked ``<!-- own-data:MARKER -->`` (a here-document stays whole, as bash
    reads it)."""
    text = DOC.read_text()
    block = text.split(f"<!-- own-data:{marker} -->", 1)[1].split("<!-- own-data:end -->", 1)[0]
    body = re.search(r"```bash\n(.*?)```", block, re.S)
    assert body, "docs/own-data.md: no bash block between the own-data markers"
    return body.group(1).rstrip("\n").split("\n")


def scratch_repository(root: Path) -> None:
    """``root`` laid out like the repository for the doc's commands: workflow, rules, config and src linked, and
    ``.venv/bin`` the running interpreter's scripts folder."""
    for name in ("workflow", "rules", "config", "src"):
        (root / name).symlink_to(REPO / name)
    (root / ".venv").mkdir()
    (root / ".venv" / "bin").symlink_to(Path(sys.executable).parent)


@pytest.mark.slow
def test_own_data_walkthrough_runs_as_written(shared_real, tmp_path):
    lines = doc_commands()
    assert lines[0].startswith("DATA=") and lines[-1].startswith(".venv/bin/eigs view ")
    scratch_repository(tmp_path)
    script = "\n".join([f"DATA={shared_real / 'ecd_slider_depth'}", *lines[1:-1]]) + "\n"
    env = {**os.environ, "EIGS_PROGRESS": "0"}
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert (tmp_path / "mine.h5").is_file() and "views" in proc.stdout
    run = tmp_path / "results" / "mine" / "b4" / "3dgs"
    assert (run / "model.ply").is_file()
    assert (tmp_path / "results" / "mine" / "b4" / "eval" / "3dgs" / "metrics.json").is_file()
    assert "3DGS" in proc.stdout  # table1.md printed
    assert probe_mp4(tmp_path / "results" / "videos" / "mine.mp4")["frames"] == 60
    assert probe_mp4(tmp_path / "mine.mp4")["frames"] == 30
    # the viewer: the doc's command with a free port, stopped once it printed its address
    view = subprocess.Popen(["bash", "-c", f"exec {lines[-1]} --port 0"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True, env=env)  # fmt: skip
    seen = []
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            line = view.stdout.readline()
            if not line:
                break
            seen.append(line)
            if "http://" in line:
                break
    finally:
        os.killpg(view.pid, signal.SIGTERM)
        view.wait(timeout=30)
    assert any("http://" in ln for ln in seen), "".join(seen)


def test_own_data_walkthrough_with_events_runs_as_written(shared_real, tmp_path):
    """The second block: a DAVIS346 AEDAT4 recording (events and APS frames) through ingest and the workflow's EDI."""
    lines = doc_commands("events")
    assert lines[0].startswith("DATA=")
    scratch_repository(tmp_path)
    script = "\n".join([f"DATA={shared_real / 'davis346_lab' / 'davis.aedat4'}", *lines[1:]]) + "\n"
    env = {**os.environ, "EIGS_PROGRESS": "0"}
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "views: 3 blurry frames" in proc.stdout
    from eigs.artifacts.edi import read_edi

    edi = read_edi(tmp_path / "results" / "davis" / "b4" / "edi.h5")
    assert edi.latent.shape[:2] == (3, 5) and not edi.sharp.any()  # every view deblurred with its events
    assert int(edi.event_count.sum()) > 10_000
    pngs = sorted((tmp_path / "results" / "davis" / "b4" / "latent").glob("*.png"))
    assert len(pngs) == 15 and all(p.name in proc.stdout for p in pngs)
