"""The ``eigs`` command: one subcommand per pipeline stage.

Each subcommand lives in its stage package as a module exposing ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int | None``. Those modules import only argparse-level
things at top level, so ``eigs --help`` stays fast; heavy imports happen inside ``run``.
User errors (:class:`eigs.errors.EigsError`) print on one line and exit 2, without a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from eigs import __version__
from eigs.errors import EigsError
from eigs.util.memory import keep_freed_memory, use_huge_pages

# subcommand name -> module path (in pipeline order). A subcommand is named for what it does and lives in the
# package of its stage (ingest, edi, sfm, init, train, evaluate, tables are packages of those names); resources ->
# metrics (the model files the metrics need), render -> evaluate (it renders a run folder, as evaluation does);
# status -> util (it reads the logs every stage writes, beside the progress bars of eigs.util.progress).
COMMANDS: dict[str, str] = {
    "scene": "eigs.scene.cli",
    "synth": "eigs.synth.cli",
    "ingest": "eigs.ingest.cli",
    "edi": "eigs.edi.cli",
    "sfm": "eigs.sfm.cli",
    "init": "eigs.init.cli",
    "train": "eigs.train.cli",
    "render": "eigs.evaluate.render_cli",
    "view": "eigs.view.cli",
    "video": "eigs.view.video_cli",
    "evaluate": "eigs.evaluate.cli",
    "tables": "eigs.tables.cli",
    "figures": "eigs.tables.figures_cli",
    "metric": "eigs.metrics.cli",
    "resources": "eigs.metrics.resources_cli",
    "status": "eigs.util.status_cli",
}


def _add_common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--threads", type=int, default=None, metavar="N", help="threads for torch/OpenMP/BLAS (default: all)"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="eigs",
        description="Event-informed Gaussian Splatting pipeline. Each subcommand is one stage; "
        "`eigs SUBCOMMAND --help` describes it.",
    )
    parser.add_argument("--version", action="version", version=f"eigs {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND")
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.epilog = (f"{p.epilog}\n\n" if p.epilog else "") + f"implemented in {module_name}"
        _add_common(p)
        p.set_defaults(_run=module.run)
    return parser


def _unraisable(info) -> None:  # noqa: ANN001 (sys.UnraisableHookArgs)
    """A full disk also fails the closing writes of objects being freed (h5py's file handles): the error line says
    it once; other unraisable exceptions are printed as Python does."""
    from eigs.util.atomic import is_disk_full

    if info.exc_value is not None and is_disk_full(info.exc_value):
        return
    sys.__unraisablehook__(info)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    keep_freed_memory()  # a step's large temporaries reuse pages instead of faulting fresh ones (eigs.util.memory)
    use_huge_pages()  # before torch loads: large tensors on 2 MB pages (eigs.util.memory)
    sys.unraisablehook = _unraisable
    try:
        if args.threads is not None:
            from eigs.util.threads import set_threads

            set_threads(args.threads)
        code = args._run(args)
    except EigsError as err:
        print(f"eigs {args.command}: error: {err}", file=sys.stderr)
        return 2
    except (OSError, RuntimeError) as err:  # a full disk outside an atomic write (which names its artifact itself)
        from eigs.util.atomic import disk_full_error, free_bytes, is_disk_full

        target = getattr(args, "output", None) or getattr(err, "filename", None)
        if not is_disk_full(err, target):
            raise
        print(f"eigs {args.command}: error: {disk_full_error(target or '.', free_bytes(target or '.'))}",
              file=sys.stderr)  # fmt: skip
        return 2
    except KeyboardInterrupt:
        print(f"eigs {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
