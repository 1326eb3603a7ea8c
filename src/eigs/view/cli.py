"""``eigs view``: open trained Gaussian runs in a 3D viewer in the browser (viser, served from this machine; works
offline). Shows the run given and, unless ``--only``, the other runs beside it that share its SfM folder (switch
between them in the panel at the same camera), the training (blue) and test (orange) cameras. Runs until Ctrl-C
or SIGTERM. Field runs (model.npz) have no Gaussians: they get a one-line error (render them with ``eigs render``).
"""

from __future__ import annotations

import argparse

HELP = "open trained Gaussian runs (model.ply) in a 3D viewer in the browser, with the scene's cameras"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", metavar="RUN_DIR", help="run folder(s) (model.ply, config.json); the first "
                   "is shown first")  # fmt: skip
    p.add_argument("--only", action="store_true", help="show only the runs given, not the sibling runs of the "
                   "first one's scene")  # fmt: skip
    p.add_argument("--sfm", default=None, help="SfM folder of the cameras (default: from the first run's "
                   "config.json, else RUN_DIR/../sfm)")  # fmt: skip
    p.add_argument("--scene", default=None, help="scene file for the background (default: from config.json, else "
                   "RUN_DIR/../../scene.h5)")  # fmt: skip
    p.add_argument("--camera", default=None, metavar="test:I|train:I", help="camera the browser opens at "
                   "(default: the first test camera, else the first training camera)")  # fmt: skip
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1: this machine "
                   "only; 0.0.0.0 for the network)")  # fmt: skip
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; the next free one when taken; 0: "
                   "any free port)")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    import logging
    import signal
    import threading

    from eigs.errors import EigsError
    from eigs.view.runs import check_gaussian_run, pick_camera, resolve_run, sibling_runs
    from eigs.view.server import Viewer, load_content

    log = logging.getLogger("eigs.view")
    first = resolve_run(args.runs[0], sfm=args.sfm, scene=args.scene)
    check_gaussian_run(first)
    runs = [first]
    for path in args.runs[1:]:
        other = resolve_run(path)
        check_gaussian_run(other)
        if other.sfm.resolve() != first.sfm.resolve():
            log.warning("%s uses SfM folder %s, not %s: its frame may differ from the cameras shown", other.path,
                        other.sfm, first.sfm)  # fmt: skip
        runs.append(other)
    if not args.only:
        given = {r.path.resolve() for r in runs}
        for path in sibling_runs(first):
            if path.resolve() in given:
                continue
            sib = resolve_run(path)
            if sib.kind == "field":
                log.info("%s: a field run (model.npz), not shown", sib.path)
                continue
            runs.append(sib)
    labels = [r.label for r in runs]
    for r in runs:  # labels must be unique in the menu
        if labels.count(r.label) > 1:
            r.label = str(r.path)
    if not first.sfm.is_dir():
        raise EigsError(first.sfm, "no such SfM folder (give it with --sfm)")
    content = load_content(runs)
    initial = pick_camera(args.camera, content.train, content.test) if args.camera else None

    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        stop.set()

    viewer = Viewer(content, host=args.host, port=args.port, initial=initial)
    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        print(f"eigs view: {len(runs)} run(s) of {first.path.parent} at {viewer.url()} (Ctrl-C stops)", flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        viewer.stop()
    log.info("viewer stopped")
    return 0
