"""``eigs ingest --format FORMAT SOURCE -o scene.h5``: read a dataset or recording into a scene file."""

from __future__ import annotations

import argparse

from eigs.ingest import FORMATS  # import-light: the package holds no reader imports at module level

HELP = "read E²NeRF layouts, HDF5/text/AEDAT/Prophesee/NumPy event recordings, ROS bags and frames into a scene file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = "Formats, conversions and the frames sidecar: docs/ingestion.md."
    parser.add_argument("--format", required=True, choices=FORMATS, help="source format")
    parser.add_argument("source", help="dataset folder or event file")
    parser.add_argument("-o", "--output", required=True, metavar="SCENE.h5", help="scene file to write (atomically)")
    parser.add_argument("--name", help="scene name (default: the source folder or file stem)")
    parser.add_argument(
        "--intrinsics",
        metavar="SPEC",
        help="FX,FY,CX,CY[,K1,K2,P1,P2[,K3]] or a file with those numbers, OpenCV convention (pixel centres at "
        "integers); overrides the source's calibration",
    )
    parser.add_argument("--sensor-size", metavar="WxH", help="sensor size when the source does not state it")
    parser.add_argument(
        "--exposure-us",
        metavar="START,END",
        help="exposure window as offsets (µs) from each frame timestamp, for sources without exposure times",
    )
    parser.add_argument(
        "--keep-events",
        choices=("exposures", "all"),
        help="keep only events inside the views' exposures, or all (default: exposures when known, else all)",
    )
    parser.add_argument("--views", metavar="SPEC", help="views to keep: indices and slices, e.g. 0:30 or ::10 or 0,4,9")
    parser.add_argument(
        "--time-window",
        metavar="START,END",
        help="keep events with START ≤ t < END and the views whose exposure lies inside (µs, source clock)",
    )
    parser.add_argument(
        "--groundtruth",
        metavar="FILE",
        help="ground-truth poses 't tx ty tz qx qy qz qw' (T_world_cam); e2nerf-real: a ground-truth scene file "
        "(eigs synth --e2nerf-real-layout writes it beside the layout), merged for scoring",
    )
    parser.add_argument(
        "--no-undistort",
        dest="undistort",
        action="store_false",
        help="keep the calibration's distortion instead of undistorting frames and events",
    )
    parser.add_argument(
        "--time-unit", choices=("s", "ms", "us", "ns"), help="h5, numpy: time unit when the file does not say"
    )
    parser.add_argument(
        "--columns", metavar="ORDER", help="numpy: column order of a plain (N, K) array, e.g. t,x,y,p (- skips one)"
    )
    parser.add_argument(
        "--topic",
        dest="topics",
        action="append",
        metavar="ROLE=TOPIC",
        help="rosbag: the topic for ROLE (events, image, camera_info, exposure); repeat for several roles",
    )
    parser.add_argument(
        "--frames", metavar="FILE", help="h5: frames sidecar (default: <stem>.frames.txt beside the file)"
    )
    parser.add_argument(
        "--frames-homography",
        metavar="FILE",
        help="raw formats: 3×3 homography from frame pixels to event pixels (frames from a second camera); the "
        "frames are warped into the event sensor's grid",
    )
    parser.add_argument(
        "--time-offset-us",
        metavar="N|auto",
        help="raw formats: frame times are on another clock, t_event = t_frame + N µs; auto (or auto:LO,HI) "
        "estimates N from the frames' brightness change and the events",
    )
    parser.add_argument(
        "--camera-response",
        choices=("linear", "srgb", "unknown"),
        help="frame intensity response (default: what the source states, else unknown)",
    )
    parser.add_argument("--contrast-threshold", type=float, help="event contrast threshold C, when known")
    parser.add_argument("--compression", default="none", choices=("none", "gzip", "lzf"), help="scene file compression")


def options_from_args(args: argparse.Namespace):  # -> IngestOptions
    """argparse namespace → :class:`eigs.ingest.options.IngestOptions` (values parsed and checked)."""
    from eigs.ingest.options import IngestOptions, parse_int_pair, parse_size
    from eigs.ingest.sync import parse_time_offset

    return IngestOptions(
        name=args.name,
        intrinsics=args.intrinsics,
        sensor_size=None if args.sensor_size is None else parse_size(args.sensor_size),
        exposure_us=None if args.exposure_us is None else parse_int_pair("--exposure-us", args.exposure_us),
        keep_events=args.keep_events,
        views=args.views,
        time_window=None if args.time_window is None else parse_int_pair("--time-window", args.time_window),
        groundtruth=args.groundtruth,
        undistort=args.undistort,
        time_unit=args.time_unit,
        frames=args.frames,
        frames_homography=args.frames_homography,
        time_offset_us=None if args.time_offset_us is None else parse_time_offset(args.time_offset_us),
        camera_response=args.camera_response,
        contrast_threshold=args.contrast_threshold,
        compression=args.compression,
        columns=getattr(args, "columns", None),
        topics=None if getattr(args, "topics", None) is None else tuple(args.topics),
    )


def run(args: argparse.Namespace) -> int:
    import logging
    import time

    from eigs.ingest import ingest

    t0 = time.perf_counter()
    text = ingest(args.format, args.source, args.output, options_from_args(args))
    print(f"wrote {args.output} in {time.perf_counter() - t0:.1f} s")
    print(text)
    logging.getLogger(__name__).debug("ingest done")
    return 0
