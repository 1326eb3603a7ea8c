"""ROS 1 and ROS 2 bags written by ``rosbags``' own writers from a built-in (synthetic) scene read back to the same
scene file as the scene's ECD text export (events, frames, exposure windows, intrinsics)."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.ingest.rosbag import typestore
from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import save_png

SMALL = {"seed": 1, "n_train": 3, "n_novel": 2, "subframes": 16, "gap_subframes": 8, "width": 32, "height": 24}
T0_NS = 1_000_123_456_000_000  # a ROS time (ns) for the bag clock (ECD text holds it in float s exactly)


@pytest.fixture(scope="module")
def scene():
    from eigs.synth.generate import generate

    return generate("toy", dict(SMALL)).scene


def _opencv(K):
    return K[0, 0], K[1, 1], K[0, 2] - 0.5, K[1, 2] - 0.5


def write_text_export(s, folder):
    """The scene as an ECD folder: events.txt (t s, x, y, p 0/1), images.txt (exposure starts), calib.txt."""
    folder.mkdir()
    t0 = T0_NS // 1000
    ev = s.events
    lines = [
        f"{(t0 + int(t)) / 1e6:.6f} {int(x)} {int(y)} {int(p > 0)}\n"
        for t, x, y, p in zip(ev.t, ev.x, ev.y, ev.p, strict=True)
    ]
    (folder / "events.txt").write_text("".join(lines))
    img = []
    for i, (a, _) in enumerate(s.frames.exposure_us):
        name = f"images/frame_{i:08d}.png"
        save_png(folder / name, s.frames.blurry[i])
        img.append(f"{(t0 + int(a)) / 1e6:.6f} {name}\n")
    (folder / "images.txt").write_text("".join(img))
    fx, fy, cx, cy = _opencv(s.camera.K)
    (folder / "calib.txt").write_text(" ".join(repr(float(v)) for v in (fx, fy, cx, cy)) + " 0 0 0 0 0\n")


def _ros_time(ts, us: int):
    ns = T0_NS + us * 1000
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def write_bag(
    s,
    path,
    ros1: bool,
    pkg: str = "dvs_msgs",
    exposure: bool = True,
    extra_events: bool = False,
    storage: str = "sqlite3",
    per_message: int = 1000,
):
    """rpg_dvs_ros layout: /dvs/events (EventArray, ``per_message`` events per message), /dvs/image_raw (stamp =
    exposure midpoint), /dvs/exposure (Int32 µs after each image), /dvs/camera_info. ROS 2 bags are stored as
    ``storage`` (``sqlite3`` or ``mcap``)."""
    ts = typestore(ros1=ros1)
    T = ts.types
    Header = T["std_msgs/msg/Header"]

    def header(us):
        kw = {"seq": 0} if ros1 else {}
        return Header(stamp=_ros_time(ts, us), frame_id="dvs", **kw)

    def ser(msg, typ):
        return ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ)

    H, W = s.camera.height, s.camera.width
    fx, fy, cx, cy = _opencv(s.camera.K)
    Kl = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64)
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    info = T["sensor_msgs/msg/CameraInfo"](
        header(0), H, W, "plumb_bob", np.zeros(5), Kl, np.eye(3).ravel(), np.zeros(12), 0, 0, roi
    )
    msgs = []  # (time µs, topic, type, message)
    ev_type, arr_type = f"{pkg}/msg/Event", f"{pkg}/msg/EventArray"
    ev = s.events
    for a in range(0, ev.t.size, per_message):
        sl = slice(a, a + per_message)
        events = [
            T[ev_type](x=int(x), y=int(y), ts=_ros_time(ts, int(t)), polarity=bool(p > 0))
            for x, y, t, p in zip(ev.x[sl], ev.y[sl], ev.t[sl], ev.p[sl], strict=True)
        ]
        msgs.append((int(ev.t[sl][-1]), "/dvs/events", arr_type, T[arr_type](header(int(ev.t[sl][-1])), H, W, events)))
    if extra_events:
        msgs.append((0, "/dvs2/events", arr_type, T[arr_type](header(0), H, W, [])))
    for i, (a, b) in enumerate(s.frames.exposure_us):
        mid = int(a + (b - a) // 2)
        img = s.frames.blurry[i]
        enc, data = ("rgb8", img) if img.shape[2] == 3 else ("mono8", img[..., 0])
        image = T["sensor_msgs/msg/Image"](header(mid), H, W, enc, 0, W * img.shape[2], data.reshape(-1).copy())
        msgs.append((int(b), "/dvs/image_raw", "sensor_msgs/msg/Image", image))
        if exposure:
            msgs.append((int(b) + 1, "/dvs/exposure", "std_msgs/msg/Int32", T["std_msgs/msg/Int32"](data=int(b - a))))
    msgs.append((0, "/dvs/camera_info", "sensor_msgs/msg/CameraInfo", info))
    msgs.sort(key=lambda m: m[0])
    if ros1:
        from rosbags.rosbag1 import Writer

        w = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
        w = Writer(path, version=9, storage_plugin=plugin)
    with w:
        conns = {}
        for _, topic, typ, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
        for us, topic, typ, msg in msgs:
            w.write(conns[topic], T0_NS + us * 1000, ser(msg, typ))


@pytest.fixture(scope="module")
def text_scene(scene, tmp_path_factory):
    d = tmp_path_factory.mktemp("text")
    write_text_export(scene, d / "toy")
    out = d / "text.h5"
    dur = int(scene.frames.exposure_us[0, 1] - scene.frames.exposure_us[0, 0])
    assert run_ingest("txt", d / "toy", out, "--exposure-us", f"0,{dur}") == 0
    return read_scene(out)


def _same(a, b):
    np.testing.assert_array_equal(a.events.t, b.events.t)
    np.testing.assert_array_equal(a.events.x, b.events.x)
    np.testing.assert_array_equal(a.events.y, b.events.y)
    np.testing.assert_array_equal(a.events.p, b.events.p)
    np.testing.assert_array_equal(a.events.view_index, b.events.view_index)
    np.testing.assert_array_equal(a.frames.blurry, b.frames.blurry)
    np.testing.assert_array_equal(a.frames.exposure_us, b.frames.exposure_us)
    np.testing.assert_array_equal(a.camera.K, b.camera.K)
    np.testing.assert_array_equal(a.camera.distortion, b.camera.distortion)
    assert (a.camera.width, a.camera.height, a.channels) == (b.camera.width, b.camera.height, b.channels)


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1", "ros2"])
def test_bag_matches_text_export(scene, text_scene, tmp_path, ros1, capsys):
    bag = tmp_path / ("toy.bag" if ros1 else "toy_ros2")
    write_bag(scene, bag, ros1)
    out = tmp_path / "bag.h5"
    assert run_ingest("rosbag", bag, out) == 0
    text = capsys.readouterr().out
    assert "exposure from /dvs/exposure" in text and "/dvs/camera_info" in text
    s = read_scene(out)
    _same(s, text_scene)
    # and the scene's own content, on the bag's absolute clock
    t0 = T0_NS // 1000
    np.testing.assert_array_equal(s.frames.exposure_us, scene.frames.exposure_us + t0)
    np.testing.assert_allclose(s.camera.K, scene.camera.K, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(s.frames.blurry, scene.frames.blurry)
    inside = np.zeros(scene.events.t.shape, bool)
    for a, b in scene.frames.exposure_us:
        inside |= (scene.events.t >= a) & (scene.events.t < b)
    np.testing.assert_array_equal(s.events.t, scene.events.t[inside] + t0)


def test_prophesee_msgs_and_exposure_option(scene, text_scene, tmp_path):
    """prophesee_event_msgs events; no exposure topic → --exposure-us offsets around the stamp (midpoint)."""
    bag = tmp_path / "p.bag"
    write_bag(scene, bag, True, pkg="prophesee_event_msgs", exposure=False)
    out = tmp_path / "bag.h5"
    half = int(scene.frames.exposure_us[0, 1] - scene.frames.exposure_us[0, 0]) // 2
    assert run_ingest("rosbag", bag, out, f"--exposure-us=-{half},{half}") == 0
    _same(read_scene(out), text_scene)


def test_ambiguous_topics_listed_then_chosen(scene, tmp_path, capsys):
    bag = tmp_path / "two.bag"
    write_bag(scene, bag, True, extra_events=True)
    err = expect_failure(capsys, "rosbag", bag, tmp_path / "s.h5")
    assert f"{bag}: 2 events topics (/dvs/events, /dvs2/events); choose one with --topic events=NAME" in err
    out = tmp_path / "s.h5"
    assert run_ingest("rosbag", bag, out, "--topic", "events=/dvs/events") == 0
    err = expect_failure(capsys, "rosbag", bag, tmp_path / "t.h5", "--topic", "events=/nope")
    assert "no topic /nope; the bag holds /dvs/camera_info, /dvs/events" in err
    err = expect_failure(
        capsys, "rosbag", bag, tmp_path / "t.h5", "--topic", "image=/dvs/events", "--topic", "events=/dvs2/events"
    )
    assert "topic /dvs/events is dvs_msgs/msg/EventArray; the image role takes sensor_msgs/msg/Image" in err


@pytest.mark.parametrize("cut", [0.3, 0.7, 0.95])
def test_truncated_bag(scene, tmp_path, capsys, cut):
    bag = tmp_path / "cut.bag"
    write_bag(scene, bag, True)
    data = bag.read_bytes()
    bag.write_bytes(data[: int(cut * len(data))])
    err = expect_failure(capsys, "rosbag", bag, tmp_path / "s.h5")
    assert err.startswith(f"eigs ingest: error: {bag}: "), err


def test_not_a_bag(tmp_path, capsys):
    f = tmp_path / "x.bag"
    f.write_bytes(b"hello")
    err = expect_failure(capsys, "rosbag", f, tmp_path / "s.h5")
    assert "not a readable ROS bag" in err


def test_cut_sqlite_database(scene, tmp_path, capsys):
    """SQLite reads pages past a cut file's end as zeros: a cut .db3 decoded to zero-tailed messages (found by
    tests/stress/test_rosbag_fuzz.py); the header's page count now refuses it."""
    bag = tmp_path / "b"
    write_bag(scene, bag, False)
    db = bag / "b.db3"
    data = db.read_bytes()
    db.write_bytes(data[: len(data) - 100])
    err = expect_failure(capsys, "rosbag", bag, tmp_path / "s.h5")
    assert f"{bag}: b.db3 is truncated: its header says {len(data) // 4096} pages of 4096 bytes" in err, err


@pytest.mark.parametrize("topic", ["/dvs/events", "/dvs/image_raw", "/dvs/exposure"])
def test_deleted_sqlite_row(scene, tmp_path, capsys, topic):
    """A row deleted from a ROS 2 bag's messages table: metadata.yaml still counts it, so the topic is short by
    one; before, the events or frames silently lost a message."""
    import sqlite3

    bag = tmp_path / "b"
    write_bag(scene, bag, False)
    con = sqlite3.connect(bag / "b.db3")
    n = con.execute("SELECT COUNT(*) FROM messages JOIN topics ON topic_id = topics.id WHERE name = ?", (topic,))
    n = n.fetchone()[0]
    con.execute(
        "DELETE FROM messages WHERE id = (SELECT MAX(messages.id) FROM messages JOIN topics ON topic_id = topics.id "
        "WHERE name = ?)",
        (topic,),
    )
    con.commit()
    con.close()
    err = expect_failure(capsys, "rosbag", bag, tmp_path / "s.h5")
    assert f"{bag}: {topic}: the bag lists {n} messages but holds {n - 1}" in err, err
