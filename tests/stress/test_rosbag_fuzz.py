"""Fuzzed ROS bags (issue #33): ROS 1 ``.bag`` files and ROS 2 bags (sqlite3 ``.db3`` and ``.mcap`` storage), written by
rosbags' own writers from a known synthetic scene, then truncated, byte-flipped, overwritten in blocks, or damaged
at the database level (deleted, garbled and re-pointed rows; a damaged ``metadata.yaml``).

Each damaged bag gives either one :class:`~eigs.errors.EigsError` whose single line starts with the bag's path
(never another exception: no traceback from inside rosbags), or a valid scene that **equals the original's** —
with one exception no reader can avoid: none of these storages checksums its messages (rosbags' MCAP writer leaves
the chunk CRC at 0, ROS 1 and sqlite3 have none), so damage that only changes message *payload* bytes can decode
to other values. A scene that differs from the original is accepted only when the damaged bag, read raw, still
holds the same topics with the same message counts and at least one message's bytes differ: the difference is
then in the recording itself, not something the reader dropped, reordered or invented.
"""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eigs.errors import EigsError
from eigs.ingest import ingest
from eigs.ingest.options import IngestOptions
from eigs.scene import read_scene
from tests.stress.budget import stress
from tests.stress.test_readers_fuzz import assert_one_line_naming, damage, mutations

SCENE = {"seed": 2, "n_train": 2, "n_novel": 1, "subframes": 16, "gap_subframes": 8, "width": 24, "height": 16}
KINDS = ("ros1", "db3", "mcap")


class Bag:
    """A written bag: its files (relative path → bytes), the file the damage goes to, and its ingested scene."""

    def __init__(self, root: Path, kind: str):
        self.kind = kind
        self.root = root
        if kind == "ros1":
            self.target = root / "rec.bag"
            self.data_name = "rec.bag"
        else:
            self.target = root / "rec"
            self.data_name = next(p.name for p in self.target.iterdir() if p.suffix in (".db3", ".mcap"))
        base = self.target if self.target.is_dir() else self.target.parent
        self.base_name = None if kind == "ros1" else self.target.name
        self.files = {p.name: p.read_bytes() for p in base.iterdir() if p.is_file() and p.name != "scene.h5"}
        if kind == "ros1":
            self.files = {"rec.bag": self.files["rec.bag"]}
        self.raw = raw_messages(self.target)
        out = root / "scene.h5"
        ingest("rosbag", str(self.target), str(out), options())
        self.scene = read_scene(out)

    def __repr__(self) -> str:  # hypothesis prints the fixture; keep it short
        return f"Bag({self.kind}, {sum(len(v) for v in self.files.values())} B)"

    def copy_to(self, directory: Path, data: bytes | None = None) -> Path:
        """Write the bag into ``directory`` (the data file replaced by ``data``); returns the path to ingest."""
        if self.kind == "ros1":
            path = directory / "rec.bag"
            path.write_bytes(self.files["rec.bag"] if data is None else data)
            return path
        path = directory / "rec"
        if path.exists():
            shutil.rmtree(path)
        path.mkdir()
        for name, b in self.files.items():
            (path / name).write_bytes(data if (data is not None and name == self.data_name) else b)
        return path


def options() -> IngestOptions:
    return IngestOptions(keep_events="all")


def raw_messages(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time ns, message bytes) of every message in log-time order, through rosbags directly."""
    from rosbags.highlevel import AnyReader

    from eigs.ingest.rosbag import typestore

    with AnyReader([path], default_typestore=typestore()) as r:
        return [(c.topic, t, bytes(raw)) for c, t, raw in r.messages()]


@pytest.fixture(scope="module")
def scene():
    from eigs.synth.generate import generate

    return generate("toy", dict(SCENE)).scene


@pytest.fixture(scope="module")
def bags(scene, tmp_path_factory) -> dict[str, Bag]:
    from tests.ingest.test_rosbag import write_bag

    out = {}
    for kind in KINDS:
        root = tmp_path_factory.mktemp(kind)
        if kind == "ros1":
            write_bag(scene, root / "rec.bag", True, per_message=500)
        else:
            write_bag(scene, root / "rec", False, storage="sqlite3" if kind == "db3" else "mcap", per_message=500)
        out[kind] = Bag(root, kind)
    return out


def same_scene(a, b) -> bool:
    pairs = [
        (a.events.t, b.events.t),
        (a.events.x, b.events.x),
        (a.events.y, b.events.y),
        (a.events.p, b.events.p),
        (a.events.view_index, b.events.view_index),
        (a.frames.blurry, b.frames.blurry),
        (a.frames.exposure_us, b.frames.exposure_us),
        (a.camera.K, b.camera.K),
        (a.camera.distortion, b.camera.distortion),
    ]
    return all(x.shape == y.shape and np.array_equal(x, y) for x, y in pairs)


def payload_changed(bag: Bag, path: Path) -> bool:
    """True when the damaged bag holds the same topics with the same message counts as the original and some
    message's bytes differ (a change no reader can detect without checksums)."""
    try:
        raw = raw_messages(path)
    except Exception:
        return False

    def counts(msgs):
        c: dict[str, int] = {}
        for topic, _, _ in msgs:
            c[topic] = c.get(topic, 0) + 1
        return c

    if counts(raw) != counts(bag.raw):
        return False
    by_topic = {}
    for topic, _, data in bag.raw:
        by_topic.setdefault(topic, []).append(data)
    damaged = {}
    for topic, _, data in raw:
        damaged.setdefault(topic, []).append(data)
    return any(by_topic[t] != damaged[t] for t in by_topic)


def check(bag: Bag, path: Path) -> str:
    """Ingest the (damaged) bag at ``path``: a one-line error naming it, or the original scene (or a payload change
    no reader can see). Returns "refused", "equal" or "payload"."""
    out = path.parent / "out.h5"
    out.unlink(missing_ok=True)
    try:
        ingest("rosbag", str(path), str(out), options())
    except EigsError as err:
        if not str(err).startswith("--"):
            assert_one_line_naming(err, path)
        assert not out.exists()
        return "refused"
    s = read_scene(out)
    if same_scene(s, bag.scene):
        return "equal"
    assert payload_changed(bag, path), "a damaged bag decoded to a different scene, with its messages intact"
    return "payload"


@pytest.mark.parametrize("kind", KINDS)
def test_truncated_bags(kind, bags, tmp_path):
    bag = bags[kind]
    data = bag.files[bag.data_name]
    seen = set()
    for frac in (0.0, 0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 0.999):
        seen.add(check(bag, bag.copy_to(tmp_path, data[: int(frac * len(data))])))
    assert seen == {"refused"}, seen


def _fuzz(kind: str):
    @stress(25)
    @given(data=st.data())
    def run(bags, tmp_path_factory, data) -> None:
        bag = bags[kind]
        raw = bag.files[bag.data_name]
        mutation = data.draw(mutations(len(raw)), label="mutation")
        check(bag, bag.copy_to(tmp_path_factory.mktemp(kind), damage(raw, mutation)))

    return run


test_fuzz_ros1 = _fuzz("ros1")
test_fuzz_db3 = _fuzz("db3")
test_fuzz_mcap = _fuzz("mcap")


def _sql(path: Path, *statements: str) -> None:
    db = next(path.glob("*.db3"))
    con = sqlite3.connect(db)
    try:
        for s in statements:
            con.execute(s)
        con.commit()
    finally:
        con.close()


def _of(topic: str) -> str:
    return f"topic_id = (SELECT id FROM topics WHERE name = '{topic}')"


def _row(which: str, topic: str) -> str:
    """``id = (the first/last row of topic)``."""
    return f"id = (SELECT {which}(id) FROM messages WHERE {_of(topic)})"


EV, IMG, EXP, INFO = "/dvs/events", "/dvs/image_raw", "/dvs/exposure", "/dvs/camera_info"
SQL_CASES = {
    "delete an event message": [f"DELETE FROM messages WHERE {_row('MIN', EV)} + 3"],
    "delete the last image": [f"DELETE FROM messages WHERE {_row('MAX', IMG)}"],
    "delete an exposure": [f"DELETE FROM messages WHERE {_row('MIN', EXP)}"],
    "delete every event": [f"DELETE FROM messages WHERE {_of(EV)}"],
    "duplicate a message": [
        f"INSERT INTO messages (topic_id, timestamp, data) SELECT topic_id, timestamp, data FROM messages "
        f"WHERE {_of(EV)} LIMIT 1"
    ],
    "re-point a row": ["UPDATE messages SET topic_id = 999 WHERE id = (SELECT MIN(id) FROM messages)"],
    "move an image to the events": [
        f"UPDATE messages SET topic_id = (SELECT id FROM topics WHERE name = '{EV}') WHERE {_row('MIN', IMG)}"
    ],
    "garble an event message": [f"UPDATE messages SET data = randomblob(length(data)) WHERE {_row('MIN', EV)}"],
    "cut an event message": [f"UPDATE messages SET data = substr(data, 1, length(data) / 2) WHERE {_row('MIN', EV)}"],
    "cut an image": [f"UPDATE messages SET data = substr(data, 1, length(data) - 7) WHERE {_row('MIN', IMG)}"],
    "empty a camera info": [f"UPDATE messages SET data = x'' WHERE {_of(INFO)}"],
    "zero an image": [f"UPDATE messages SET data = zeroblob(length(data)) WHERE {_row('MIN', IMG)}"],
    "garble a type": [f"UPDATE topics SET type = 'dvs_msgs/msg/Nonexistent' WHERE name = '{EV}'"],
    "drop the topics": ["DROP TABLE topics"],
    "drop the messages": ["DROP TABLE messages"],
    "shuffle the times": ["UPDATE messages SET timestamp = 0 WHERE id = (SELECT MAX(id) FROM messages)"],
}
MUST_REFUSE = ("delete", "duplicate", "cut", "drop", "empty", "zero", "move", "re-point")


@pytest.mark.parametrize("case", list(SQL_CASES))
def test_sqlite_rows(case, bags, tmp_path):
    """Deleted, duplicated, re-pointed, garbled and cut rows of the ROS 2 sqlite3 storage."""
    bag = bags["db3"]
    path = bag.copy_to(tmp_path)
    _sql(path, *SQL_CASES[case])
    result = check(bag, path)
    if case.startswith(MUST_REFUSE):
        assert result == "refused", (case, result)


@pytest.mark.parametrize("kind", ["db3", "mcap"])
@pytest.mark.parametrize(
    "case", ["no metadata", "truncated metadata", "wrong count", "garbled metadata", "no data file"]
)
def test_metadata(kind, case, bags, tmp_path):
    """A missing, cut or inconsistent ``metadata.yaml`` (or a missing storage file) of a ROS 2 bag."""
    bag = bags[kind]
    path = bag.copy_to(tmp_path)
    meta = path / "metadata.yaml"
    text = meta.read_text()
    if case == "no metadata":
        meta.unlink()
    elif case == "truncated metadata":
        meta.write_text(text[: len(text) // 2])
    elif case == "wrong count":
        lines = text.splitlines(keepends=True)
        k = next(i for i, ln in enumerate(lines) if ln.startswith("  - message_count:"))  # the first topic's
        head, _, n = lines[k].rpartition(":")
        lines[k] = f"{head}: {int(n) + 1}\n"
        meta.write_text("".join(lines))
    elif case == "garbled metadata":
        meta.write_text(text.replace("rosbag2_bagfile_information", "rosbag2_bagfile_informatio"))
    else:
        (path / bag.data_name).unlink()
    assert check(bag, path) == "refused", case
