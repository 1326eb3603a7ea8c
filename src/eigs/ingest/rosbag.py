"""ROS 1 and ROS 2 bags (``--format rosbag``) through ``rosbags`` (PyPI, pure Python; no ROS install).

Topics by role, each chosen by ``--topic ROLE=NAME`` or, when not given, as the only topic of its type:

- ``events``: ``dvs_msgs/EventArray`` (rpg_dvs_ros) or ``prophesee_event_msgs/EventArray``: x, y, ts (ROS time),
  polarity (bool);
- ``image``: ``sensor_msgs/Image`` (``mono8``, ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``) with ``header.stamp``;
- ``camera_info``: ``sensor_msgs/CameraInfo`` (``plumb_bob`` or no distortion): K, D, size (OpenCV convention);
- ``exposure``: ``std_msgs/Int32`` (µs; also Float32/64 holding whole µs) on a topic whose name contains
  ``exposure``: the exposure time of each frame.

Several candidates for a role (or none with the name given) is an error that lists the bag's topics of that type.
The custom message types are registered with rosbags' typestore from the ``.msg`` definitions below (identical in
both packages); ROS 1 bags also carry their own definitions, which rosbags reads.

- **Time**: ROS time (s, ns) → µs, ns rounded half up; kept absolute (the bag's clock).
- **Exposure**: rpg_dvs_ros stamps a frame at its exposure midpoint (libcaer's frame timestamp = exposure start +
  length / 2, integer µs) and publishes the exposure length (µs) on ``/dvs/exposure`` after each frame: the k-th
  exposure message belongs to the k-th image (counts must agree) and the window is
  ``[stamp − E // 2, stamp − E // 2 + E)``. Without an exposure topic, ``--exposure-us START,END`` adds offsets to
  the stamps (as for text recordings), else the frames are instants.
- **Frames**: ``rgb8``/``bgr8`` → RGB, ``rgba8``/``bgra8`` composited on black, ``mono8`` gray; rows may be padded
  (``step``). Other encodings (16-bit, Bayer) are refused.
- **Memory**: messages are read one at a time; events are re-batched into chunks of :data:`CHUNK_EVENTS`; frame
  pixels are decoded for the kept views only (a second pass).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.chunks import Rebatcher, TimeOrder
from eigs.ingest.options import IngestOptions, opencv_to_K
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import to_pixel

log = logging.getLogger(__name__)

CHUNK_EVENTS = 1 << 22

EVENT_MSG = """\
uint16 x
uint16 y
time ts
bool polarity
"""
EVENT_ARRAY_MSG = """\
std_msgs/Header header
uint32 height
uint32 width
{pkg}/Event[] events
"""
CUSTOM_PACKAGES = ("dvs_msgs", "prophesee_event_msgs")

EVENT_TYPES = tuple(f"{p}/msg/EventArray" for p in CUSTOM_PACKAGES)
IMAGE_TYPES = ("sensor_msgs/msg/Image",)
INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)
EXPOSURE_TYPES = ("std_msgs/msg/Int32", "std_msgs/msg/Float32", "std_msgs/msg/Float64")
ROLES = {"events": EVENT_TYPES, "image": IMAGE_TYPES, "camera_info": INFO_TYPES, "exposure": EXPOSURE_TYPES}
ENCODINGS = {"mono8": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}


def custom_types() -> dict[str, Any]:
    """Type definitions of dvs_msgs and prophesee_event_msgs (Event, EventArray) for ``Typestore.register``."""
    from rosbags.typesys import get_types_from_msg

    types: dict[str, Any] = {}
    for pkg in CUSTOM_PACKAGES:
        types.update(get_types_from_msg(EVENT_MSG, f"{pkg}/msg/Event"))
        types.update(get_types_from_msg(EVENT_ARRAY_MSG.format(pkg=pkg), f"{pkg}/msg/EventArray"))
    return types


def typestore(ros1: bool = False):
    """A rosbags typestore (ROS 1 Noetic or the latest ROS 2) with our custom event types registered."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    ts.register(custom_types())
    return ts


def _time_us(stamp) -> int:
    """ROS time (sec, nanosec) → int µs, ns rounded half up."""
    ns = int(getattr(stamp, "nanosec", getattr(stamp, "nsec", 0)))
    return int(stamp.sec) * 1_000_000 + (ns + 500) // 1000


class _Bag:
    """An open bag: its connections by topic and a message iterator that turns rosbags errors into EigsError."""

    def __init__(self, path: Path):
        from rosbags.highlevel import AnyReader

        self.path = path
        if path.is_dir():
            for db in sorted(path.glob("*.db3")):
                check_sqlite_size(path, db)
        try:
            self.reader = AnyReader([path], default_typestore=typestore())
            self.reader.open()
        except Exception as err:  # rosbags raises its own error types for unreadable bags
            raise EigsError(path, f"not a readable ROS bag ({_short(err)})") from None
        self.topics: dict[str, tuple[str, list]] = {}
        for c in self.reader.connections:
            t = self.topics.setdefault(c.topic, (c.msgtype, []))
            if t[0] != c.msgtype:
                raise EigsError(path, f"topic {c.topic} carries two message types ({t[0]}, {c.msgtype})")
            t[1].append(c)

    def close(self) -> None:
        try:
            self.reader.close()
        except Exception:  # closing a damaged bag must not hide the error being reported
            pass

    def count(self, topic: str) -> int:
        return sum(c.msgcount for c in self.topics[topic][1])

    def messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """(index, deserialized message) of ``topic`` in log-time order; the count read must be the bag's count
        (ROS 1 connection index, ROS 2 ``metadata.yaml``): rows missing from or added to the storage are errors."""
        conns = self.topics[topic][1]
        expected = self.count(topic)
        it = self.reader.messages(connections=conns)
        k = 0
        while True:
            try:
                conn, _, raw = next(it)
                msg = self.reader.deserialize(raw, conn.msgtype)
            except StopIteration:
                if k != expected:
                    raise EigsError(
                        self.path,
                        f"{topic}: the bag lists {expected} messages but holds {k} (messages lost or added: damaged)",
                    ) from None
                return
            except EigsError:
                raise
            except Exception as err:
                raise EigsError(
                    self.path, f"message {k} of {topic} is truncated or corrupted ({_short(err)})"
                ) from None
            yield k, msg
            k += 1


def check_sqlite_size(bag: Path, db: Path) -> None:
    """Refuse a ROS 2 ``.db3`` shorter than its own header says (a cut copy): SQLite reads the missing pages as
    zeros, so a cut database can otherwise decode to messages whose tail bytes are zeros.

    SQLite file header (sqlite.org "Database File Format" §1.3): bytes 16–17 page size (big-endian; 1 means
    65536), 24–27 file change counter, 28–31 database size in pages, valid when bytes 92–95 (version-valid-for)
    equal the change counter."""
    try:
        with open(db, "rb") as fh:
            head = fh.read(100)
        size = db.stat().st_size
    except OSError as err:
        raise EigsError(bag, f"cannot read {db.name} ({err.strerror or err})") from None
    if len(head) < 100 or not head.startswith(b"SQLite format 3\0"):
        raise EigsError(bag, f"{db.name} is not an SQLite 3 database ({size} bytes, starts with {head[:16]!r})")
    page = int.from_bytes(head[16:18], "big")
    page = 65536 if page == 1 else page
    pages = int.from_bytes(head[28:32], "big")
    if head[24:28] == head[92:96] and pages and page >= 512 and size < pages * page:
        raise EigsError(
            bag, f"{db.name} is truncated: its header says {pages} pages of {page} bytes, the file ends at byte {size}"
        )


def _short(err: Exception) -> str:
    """One line (≤ 160 characters) describing an exception from rosbags or sqlite; Python's own error types (a
    KeyError for an unknown type name, an AssertionError, a UnicodeDecodeError) are named, their text alone is
    cryptic."""
    text = " ".join(str(err).split())
    if not text or type(err).__module__ == "builtins":
        text = f"{type(err).__name__}: {text}" if text else type(err).__name__
    return text[:160]


def choose_topics(bag: _Bag, given: tuple[str, ...] | None) -> dict[str, str | None]:
    """Role → topic (or None when the bag has none of that type and none was asked for)."""
    chosen: dict[str, str | None] = {}
    asked: dict[str, str] = {}
    for item in given or ():
        role, sep, name = item.partition("=")
        role = role.strip().replace("-", "_")
        if not sep or role not in ROLES or not name.strip():
            raise EigsError("--topic", f"expected ROLE=TOPIC with ROLE one of {', '.join(ROLES)}, got {item!r}")
        if role in asked:
            raise EigsError("--topic", f"{role} given twice")
        asked[role] = name.strip()
    for role, types in ROLES.items():
        cands = [t for t, (mt, _) in bag.topics.items() if mt in types]
        if role == "exposure":
            cands = [t for t in cands if "exposure" in t.rsplit("/", 1)[-1].lower()]
        if role in asked:
            name = asked[role]
            if name not in bag.topics:
                raise EigsError(
                    bag.path, f"no topic {name}; the bag holds {', '.join(sorted(bag.topics)) or 'no topics'}"
                )
            if bag.topics[name][0] not in types:
                raise EigsError(
                    bag.path, f"topic {name} is {bag.topics[name][0]}; the {role} role takes {', '.join(types)}"
                )
            chosen[role] = name
        elif len(cands) > 1:
            raise EigsError(
                bag.path,
                f"{len(cands)} {role} topics ({', '.join(sorted(cands))}); choose one with --topic {role}=NAME",
            )
        else:
            chosen[role] = cands[0] if cands else None
    return chosen


def _channels(encoding: str) -> int:
    """Channels an image encoding gives in the scene (1 gray, 3 colour; 0 for encodings eigs refuses)."""
    return {1: 1, 3: 3, 4: 3}.get(ENCODINGS.get(encoding.lower(), 0), 0)


def _image(path: Path, msg, k: int) -> np.ndarray:
    """sensor_msgs/Image → (H, W, C) uint8, C = 1 or 3 (RGB; alpha composited on black)."""
    from eigs.ingest.images import composite_on_black

    enc = str(msg.encoding).lower()
    if enc not in ENCODINGS:
        raise EigsError(path, f"image {k} has encoding {msg.encoding!r}; eigs reads {', '.join(ENCODINGS)}")
    c = ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if step < w * c or data.size != h * step:
        raise EigsError(path, f"image {k}: {data.size} bytes for {w}×{h} {enc} with step {step}")
    a = data.reshape(h, step)[:, : w * c].reshape(h, w, c)
    if enc.startswith("bgr"):
        a = np.concatenate([a[..., 2::-1], a[..., 3:]], axis=2)
    if c == 4:
        a = composite_on_black(a)
    return np.ascontiguousarray(a)


def _camera_info(bag: _Bag, topic: str) -> tuple[np.ndarray, np.ndarray, int, int, int]:
    """(K ours, distortion (5,), width, height, messages) from the CameraInfo topic; all messages must agree."""
    first = None
    n = 0
    for k, msg in bag.messages(topic):
        Km = np.asarray(getattr(msg, "k", getattr(msg, "K", None)), dtype=np.float64).reshape(-1)
        D = np.asarray(getattr(msg, "d", getattr(msg, "D", None)), dtype=np.float64).reshape(-1)
        model = str(msg.distortion_model)
        key = (tuple(Km), tuple(D), model, int(msg.width), int(msg.height))
        if first is None:
            first = key
        elif key != first:
            raise EigsError(bag.path, f"camera info message {k} on {topic} differs from the first one")
        n += 1
    if first is None:
        raise EigsError(bag.path, f"topic {topic} holds no camera info message")
    Km, D, model, w, h = first
    K = np.asarray(Km).reshape(3, 3)
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[0, 1] != 0 or K[2, 2] != 1:
        raise EigsError(bag.path, f"camera info on {topic} has K = {list(Km)}, not a pinhole matrix")
    if any(D) and model not in ("plumb_bob", "radtan"):
        raise EigsError(bag.path, f"camera info on {topic}: distortion model {model!r}; eigs reads plumb_bob")
    if len(D) > 5 and any(D[5:]):
        raise EigsError(bag.path, f"camera info on {topic} has {len(D)} distortion coefficients; eigs reads 5")
    dist = np.zeros(5)
    dist[: min(5, len(D))] = D[:5]
    return opencv_to_K(K[0, 0], K[1, 1], K[0, 2], K[1, 2]), dist, w, h, n


def _exposures(bag: _Bag, topic: str, stamps: np.ndarray) -> np.ndarray:
    """(V, 2) int64 [start, end) µs from the exposure topic (k-th message ↔ k-th image, stamp = midpoint)."""
    vals = []
    for k, msg in bag.messages(topic):
        v = float(msg.data)
        if not np.isfinite(v) or v <= 0 or v != round(v):
            raise EigsError(bag.path, f"exposure message {k} on {topic} is {msg.data}, not a positive whole µs")
        vals.append(int(round(v)))
    if len(vals) != stamps.size:
        raise EigsError(
            bag.path,
            f"{topic} has {len(vals)} exposure messages for {stamps.size} images; give --topic exposure=NAME or "
            "--exposure-us START,END",
        )
    e = np.asarray(vals, dtype=np.int64)
    start = stamps - e // 2
    return np.stack([start, start + e], axis=1)


def read_bag_events(path: Path, topic: str, width: int, height: int, chunk: int = CHUNK_EVENTS) -> Iterator[EventChunk]:
    """Stream the events of ``topic`` as converted chunks (x, y uint16; t int64 µs; p int8 ±1)."""
    bag = _Bag(path)
    where = str(path)
    order = TimeOrder(path, "messages or events out of order")
    batch = Rebatcher(chunk)
    offset = 0
    try:
        for k, msg in bag.messages(topic):
            evs = msg.events
            n = len(evs)
            if n == 0:
                continue
            sec = np.fromiter((e.ts.sec for e in evs), np.int64, n)
            nsec = np.fromiter((getattr(e.ts, "nanosec", getattr(e.ts, "nsec", 0)) for e in evs), np.int64, n)
            if np.any((nsec < 0) | (nsec >= 1_000_000_000)):
                raise EigsError(path, f"message {k} of {topic}: an event timestamp has nanoseconds ≥ 1e9")
            t = sec * 1_000_000 + (nsec + 500) // 1000
            order(t, offset)
            x = to_pixel(np.fromiter((e.x for e in evs), np.int64, n), width, "x", where, offset)
            y = to_pixel(np.fromiter((e.y for e in evs), np.int64, n), height, "y", where, offset)
            p = np.where(np.fromiter((bool(e.polarity) for e in evs), bool, n), np.int8(1), np.int8(-1))
            offset += n
            yield from batch.add((x, y, t, p))
        yield from batch.rest()
    finally:
        bag.close()


def open_rosbag_source(source: str, opts: IngestOptions) -> RawSource:
    """Open a ROS 1 (``.bag``) or ROS 2 (folder with ``metadata.yaml``, or its ``.db3``/``.mcap``) bag."""
    from eigs.ingest.poses import read_groundtruth

    opts.refuse("rosbag", "time_unit", "frames")
    path = Path(source)
    if not path.exists():
        raise EigsError(path, "no such file or folder")
    if path.is_file() and path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        path = path.parent
    bag = _Bag(path)
    try:
        roles = choose_topics(bag, opts.topics)
        if roles["events"] is None and roles["image"] is None:
            listing = ", ".join(f"{t} ({mt})" for t, (mt, _) in sorted(bag.topics.items()))
            raise EigsError(path, f"no event or image topic; the bag holds {listing or 'nothing'}")
        src = RawSource(path=path, fmt="rosbag", name=path.stem if path.is_file() else path.name)
        src.notes.append("topics: " + ", ".join(f"{r} {t}" for r, t in roles.items() if t is not None))
        sizes: dict[str, tuple[int, int]] = {}
        if roles["camera_info"] is not None:
            K, dist, w, h, n = _camera_info(bag, roles["camera_info"])
            if opts.intrinsics is None:
                src.K, src.distortion = K, dist
                src.calibration = f"{roles['camera_info']} ({n} messages)"
            sizes[roles["camera_info"]] = (w, h)
        if roles["events"] is not None:
            for _, msg in bag.messages(roles["events"]):
                if int(msg.width) and int(msg.height):
                    sizes[roles["events"]] = (int(msg.width), int(msg.height))
                break
            src.n_events = None
        if roles["image"] is not None:
            stamps, shape = [], None
            for k, msg in bag.messages(roles["image"]):
                stamps.append(_time_us(msg.header.stamp))
                s = (int(msg.width), int(msg.height), str(msg.encoding))
                if shape is None:
                    shape = s
                elif s[:2] != shape[:2] or _channels(s[2]) != _channels(shape[2]):
                    raise EigsError(
                        path,
                        f"image {k} on {roles['image']} is {s[0]}×{s[1]} {s[2]}, the first {shape[0]}×{shape[1]} "
                        f"{shape[2]}",
                    )
            if stamps:
                assert shape is not None
                sizes[roles["image"]] = shape[:2]
                t = np.asarray(stamps, dtype=np.int64)
                back = np.flatnonzero(np.diff(t) < 0)
                if back.size:
                    raise EigsError(path, f"image stamps on {roles['image']} go backwards at image {int(back[0]) + 1}")
                src.n_frames = t.size
                src.frame_t_us = t
                if roles["exposure"] is not None:
                    src.exposure_us = _exposures(bag, roles["exposure"], t)
                    src.notes.append(f"exposure from {roles['exposure']} (µs, frame stamp = exposure midpoint)")
                image_topic = roles["image"]

                def load(idx: np.ndarray) -> np.ndarray:
                    want = {int(i): j for j, i in enumerate(idx)}
                    out: list[np.ndarray | None] = [None] * len(idx)
                    b = _Bag(path)
                    try:
                        for k, msg in b.messages(image_topic):
                            if k in want:
                                out[want[k]] = _image(path, msg, k)
                    finally:
                        b.close()
                    if any(a is None for a in out):
                        raise EigsError(path, "the bag changed while reading (image count differs between passes)")
                    return np.stack(out)  # type: ignore[arg-type]

                src.load_frames = load
        if len(set(sizes.values())) > 1:
            raise EigsError(path, "sizes disagree: " + ", ".join(f"{t} {w}×{h}" for t, (w, h) in sizes.items()))
        if sizes:
            src.width, src.height = next(iter(sizes.values()))
    finally:
        bag.close()
    if opts.groundtruth is not None:
        src.trajectory = read_groundtruth(Path(opts.groundtruth))
    if roles["events"] is not None:
        ev_topic = roles["events"]
        src.events = lambda w, h: read_bag_events(path, ev_topic, w, h)
    return src
