"""The GPU check (issue 34): a small bundle of one scene's prepared artifacts, the trainings of bench/gpu_check.sh,
and the JSON they report.

``bench/gpu_check.sh`` runs on a bare GPU machine with a CUDA PyTorch: it installs gsplat from carried wheels, runs
the CUDA tests, then calls this module to train and evaluate two runs of the default suite (``eigs+``, ``edi-3dgs``)
on the bundle and to write ``gpu_check.json``. The same ``run`` subcommand with ``--device cpu`` gives the CPU
baseline from the same bundle (bench/gpu_check_cpu_baseline.json).

Subcommands:
  ``bundle``  copy a workflow directory's artifacts of one scene (scene.h5 without its raw events, b{B}/edi.h5,
              b{B}/sfm/{poses,test_cameras}.h5, the HDF5 datasets gzip-compressed; b{B}/init.ply) and the
              LPIPS-alex weights into a folder with a MANIFEST.json (sha256 of every file and of its source, the
              runs' `eigs train --config` JSON resolved from config/config.yaml);
  ``verify``  check a bundle's files against its manifest;
  ``run``     train and evaluate the bundle's runs with ``python -m eigs.cli`` (the rules' commands, plus
              ``--device``), writing one JSON of what was measured;
  ``report``  assemble the final JSON: environment (GPU, torch, gsplat), conformance tests (JUnit XML), the gsplat
              build time, the runs and, given a baseline, the PSNR differences to it.

Run: ``.venv/bin/python bench/gpu_check.py bundle --directory WORKFLOW_DIR -o .gpu_bundle`` (``make gpu-bundle``).
Only the standard library is imported at module level, and ``run``/``report``/``verify`` need no third-party
package beyond what ``eigs`` needs (no yaml), so the module runs on the GPU machine's plain Python.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
BUNDLE_FORMAT = "eigs-gpu-bundle"
REPORT_FORMAT = "eigs-gpu-check"
DEFAULT_RUNS = ("eigs+", "edi-3dgs")
DEFAULT_MAX_MIB = 30.0
PSNR_TOLERANCE_DB = 0.3
# The files of one scene that `eigs train` and `eigs evaluate` read (rules/train.smk, rules/evaluate.smk): the SfM
# folder contributes only poses.h5 and test_cameras.h5 (eigs.artifacts.poses); evaluation needs LPIPS-alex.
SCENE_FILES = ("scene.h5",)
BIN_FILES = ("edi.h5", "sfm/poses.h5", "sfm/test_cameras.h5", "init.ply")
LPIPS_FILES = ("MANIFEST.json", "alex.pt")


class CheckError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


# ----------------------------------------------------------------------------------------------- small helpers


def sha256(path: Path) -> str:
    """Hex sha256 of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def write_json(path: Path, doc: dict) -> None:
    """Write ``doc`` as indented JSON atomically (eigs.util.atomic when importable, else a same-folder rename)."""
    text = json.dumps(doc, indent=2, sort_keys=False) + "\n"
    try:
        from eigs.util.atomic import atomic_path
    except ImportError:  # the module must stay usable before eigs is importable (e.g. `verify` on a bare machine)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
        return
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def safe_name(run: str) -> str:
    """A run name as a file name of letters, digits, '.', '_' and '-' only (the device returns no other names):
    '+' becomes '-plus'."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", run.replace("+", "-plus"))


def train_config_json(spec: dict) -> str:
    """A run's `eigs train --config` JSON exactly as rules/common.smk ``train_config_json`` builds it."""
    values = {"method": spec["method"], **spec.get("options", {})}
    return json.dumps(values, sort_keys=True, separators=(",", ":"))


def parse_runs(text: str) -> list[str]:
    """Comma-separated run names, at least one, no duplicates."""
    runs = [r.strip() for r in text.split(",") if r.strip()]
    if not runs:
        raise CheckError("--runs: give at least one run name")
    if len(set(runs)) != len(runs):
        raise CheckError(f"--runs: a run is named twice in {text!r}")
    return runs


# ----------------------------------------------------------------------------------------------- the bundle


def resolve_runs(config: dict, runs: list[str]) -> dict[str, dict]:
    """For each run of the suite config (already YAML-loaded, anchors resolved): its B and `--config` JSON."""
    table = config.get("runs") or {}
    bins_default = int((config.get("edi") or {}).get("bins", [4])[0])
    out = {}
    for run in runs:
        if run not in table:
            raise CheckError(f"--runs: {run!r} is not a run of the config (runs: {', '.join(sorted(table))})")
        spec = table[run]
        out[run] = {"method": spec["method"], "bins": int(spec.get("bins", bins_default)),
                    "config": train_config_json(spec)}  # fmt: skip
    return out


def bundle_sources(directory: Path, resources: Path, scene: str, bins: list[int]) -> dict[str, Path]:
    """Bundle-relative path -> source file, for one scene at the given B values."""
    src = {f"{scene}/{name}": directory / "results" / scene / name for name in SCENE_FILES}
    for b in sorted(set(bins)):
        for name in BIN_FILES:
            src[f"{scene}/b{b}/{name}"] = directory / "results" / scene / f"b{b}" / name
    for name in LPIPS_FILES:
        src[f"resources/lpips/{name}"] = resources / "lpips" / name
    return src


def copy_h5(src: Path, dst: Path, skip: tuple[str, ...] = ()) -> None:
    """Copy an HDF5 artifact, leaving out the top-level groups ``skip``, with every dataset over 4 KiB stored
    gzip-compressed (lossless: the arrays read back identical; the readers do not depend on the storage).
    Attributes of the file, groups and datasets are copied as they are."""
    import h5py

    def visit(gin: h5py.Group, gout: h5py.Group) -> None:
        for key, value in gin.attrs.items():
            gout.attrs[key] = value
        for name, item in gin.items():
            if gin.name == "/" and name in skip:
                continue
            if isinstance(item, h5py.Group):
                visit(item, gout.create_group(name))
            elif item.nbytes > 4096 and item.shape != () and item.dtype.kind in "biuf":
                ds = gout.create_dataset(name, data=item[()], compression="gzip", compression_opts=4, shuffle=True)
                for key, value in item.attrs.items():
                    ds.attrs[key] = value
            else:  # small or non-numeric: an exact copy
                gin.copy(item, gout, name)

    with h5py.File(src, "r") as fin, h5py.File(dst, "w") as fout:
        visit(fin, fout)


def make_bundle(
    directory: Path, resources: Path, config: dict, scene: str, runs: list[str], out: Path, max_mib: float
) -> dict:
    """Copy one scene's artifacts and the LPIPS-alex weights into ``out`` and write ``out/MANIFEST.json``."""
    resolved = resolve_runs(config, runs)
    if scene not in (config.get("scenes") or {}):
        raise CheckError(f"--scene: {scene!r} is not a scene of the config")
    sources = bundle_sources(directory, resources, scene, [r["bins"] for r in resolved.values()])
    missing = [str(p) for p in sources.values() if not p.is_file()]
    if missing:
        raise CheckError(f"missing artifact(s) {', '.join(missing)}: run the workflow for {scene} first")
    tmp = out.with_name(f".{out.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    files = {}
    for rel, path in sources.items():
        dst = tmp / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        if path.name == "scene.h5":
            # the raw events (~120 MB for chair) are read by neither `eigs train` nor `eigs evaluate` (both open
            # the scene with events=False; the event losses read the EDI artifact)
            copy_h5(path, dst, skip=("events",))
        elif path.suffix == ".h5":
            copy_h5(path, dst)
        else:
            shutil.copyfile(path, dst)
        files[rel] = {"sha256": sha256(dst), "bytes": dst.stat().st_size, "source_sha256": sha256(path)}
    total = sum(f["bytes"] for f in files.values())
    if total > max_mib * 2**20:
        shutil.rmtree(tmp, ignore_errors=True)
        raise CheckError(f"bundle would be {total / 2**20:.1f} MiB, over --max-mib {max_mib:g}")
    manifest = {
        "format": BUNDLE_FORMAT,
        "version": 1,
        "scene": scene,
        "runs": resolved,
        "files": files,
        "bytes": total,
        "scene_events": "dropped (not read by eigs train / eigs evaluate)",
        "source": {"directory": str(directory), "commit": git_commit(directory)},
    }
    (tmp / "MANIFEST.json").write_text(json.dumps(manifest, indent=2) + "\n")
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    return manifest


def read_manifest(bundle: Path) -> dict:
    """A bundle's manifest; one-line errors for a missing or foreign one."""
    path = bundle / "MANIFEST.json"
    if not path.is_file():
        raise CheckError(f"{path}: no bundle manifest (make one with `bench/gpu_check.py bundle`)")
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise CheckError(f"{path}: not JSON ({err})") from err
    if doc.get("format") != BUNDLE_FORMAT:
        raise CheckError(f"{path}: not an {BUNDLE_FORMAT} manifest")
    return doc


def verify_bundle(bundle: Path) -> dict:
    """The manifest, after checking every file's size and sha256."""
    doc = read_manifest(bundle)
    for rel, want in doc["files"].items():
        path = bundle / rel
        if not path.is_file():
            raise CheckError(f"{path}: missing from the bundle")
        if path.stat().st_size != want["bytes"] or sha256(path) != want["sha256"]:
            raise CheckError(f"{path}: checksum mismatch; rebuild the bundle")
    return doc


def git_commit(directory: Path) -> str | None:
    """HEAD of the git checkout holding ``directory`` (None outside git)."""
    try:
        res = subprocess.run(["git", "-C", str(directory), "rev-parse", "HEAD"], capture_output=True, text=True,
                             check=False)  # fmt: skip
    except OSError:
        return None
    return res.stdout.strip() or None


# ----------------------------------------------------------------------------------------------- runs


def run_paths(bundle: Path, scene: str, bins: int) -> dict[str, Path]:
    """The four training inputs and the resources folder inside a bundle."""
    base = bundle / scene
    return {"scene": base / "scene.h5", "edi": base / f"b{bins}" / "edi.h5", "sfm": base / f"b{bins}" / "sfm",
            "init": base / f"b{bins}" / "init.ply", "resources": bundle / "resources"}  # fmt: skip


def commands(bundle: Path, manifest: dict, run: str, work: Path, device: str, threads: int) -> dict[str, list[str]]:
    """The `eigs train` and `eigs evaluate` argument lists of one run (rules/train.smk, rules/evaluate.smk), with
    ``--device``; ``python -m eigs.cli`` stands for the `eigs` script."""
    spec = manifest["runs"][run]
    p = run_paths(bundle, manifest["scene"], spec["bins"])
    run_dir = work / safe_name(run)
    eigs = [sys.executable, "-m", "eigs.cli"]
    train = [*eigs, "train", str(p["scene"]), str(p["edi"]), str(p["sfm"]), str(p["init"]), "-o", str(run_dir),
             "--config", spec["config"], "--device", device, "--threads", str(threads)]  # fmt: skip
    evaluate = [*eigs, "evaluate", str(run_dir), str(p["scene"]), str(p["sfm"]), "-o",
                str(work / "eval" / safe_name(run) / "metrics.json"), "--resources", str(p["resources"]),
                "--device", device, "--threads", str(threads)]  # fmt: skip
    return {"train": train, "evaluate": evaluate}


def step_seconds(log_csv: Path) -> float | None:
    """Steady-state seconds per step from a train_log.csv: the wall-clock slope between its first and last logged
    rows (leaves out the start: data loading, CUDA context, first kernel loads). None with fewer than two rows."""
    with open(log_csv, newline="") as f:
        rows = [(int(r["step"]), float(r["wall_s"])) for r in csv.DictReader(f)]
    if len(rows) < 2 or rows[-1][0] <= rows[0][0]:
        return None
    return (rows[-1][1] - rows[0][1]) / (rows[-1][0] - rows[0][0])


def summarize_run(run_dir: Path, metrics_json: Path) -> dict[str, Any]:
    """What one trained and evaluated run measured: PSNR/SSIM/LPIPS, steps, times, Gaussians, device."""
    cfg = json.loads((run_dir / "config.json").read_text())
    m = json.loads(metrics_json.read_text())
    steps = int(m["steps"])
    train_s = float(m["train_seconds"])
    out: dict[str, Any] = {
        "method": m.get("method"),
        "device": m.get("device"),
        "train_device": cfg.get("run", {}).get("device"),
        "torch": cfg.get("run", {}).get("torch_version"),
        "steps": steps,
        "train_seconds": train_s,
        "seconds_per_step": train_s / steps if steps else None,
        "steady_seconds_per_step": step_seconds(run_dir / "train_log.csv"),
        "n_gaussians": m.get("n_gaussians"),
        "render_ms": m.get("render_ms"),
    }
    for group in ("novel", "blur"):
        g = m["metrics"].get(group, {})
        for key in ("psnr", f"ssim_{m.get('ssim_table_mode', 'skimage')}", f"lpips_{m.get('lpips_net', 'alex')}"):
            if key in g:
                out[f"{group}_{key.split('_')[0]}"] = g[key]
    return out


def tail(path: Path, n: int = 5) -> str:
    """The last ``n`` lines of a text file ('' if absent)."""
    if not path.is_file():
        return ""
    return " | ".join(path.read_text(errors="replace").splitlines()[-n:])


def child_cpu_seconds() -> float:
    """User + system CPU seconds of the finished child processes so far."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_all(bundle: Path, runs: list[str], work: Path, device: str, threads: int, out_json: Path) -> dict:
    """Train and evaluate each run in turn, writing ``out_json`` after each (a cut-short check keeps what it
    measured). A failed command is recorded with its log's tail and the next run goes on."""
    manifest = verify_bundle(bundle)
    unknown = [r for r in runs if r not in manifest["runs"]]
    if unknown:
        raise CheckError(f"--runs: {', '.join(unknown)} not in the bundle (runs: {', '.join(manifest['runs'])})")
    if threads < 1:
        raise CheckError("--threads: must be >= 1")
    work.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {"device": device, "threads": threads, "scene": manifest["scene"], "runs": {}}
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    for run in runs:
        cmds = commands(bundle, manifest, run, work, device, threads)
        entry: dict[str, Any] = {"config": manifest["runs"][run]["config"], "bins": manifest["runs"][run]["bins"]}
        for stage, cmd in cmds.items():
            log = work / "logs" / f"{safe_name(run)}_{stage}.log"
            log.parent.mkdir(parents=True, exist_ok=True)
            print(f"gpu_check: {run}: {stage} on {device} ...", flush=True)
            t0, c0 = time.perf_counter(), child_cpu_seconds()
            with open(log, "w") as f:
                rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, check=False).returncode
            entry[f"{stage}_wall_s"] = round(time.perf_counter() - t0, 3)
            entry[f"{stage}_cpu_s"] = round(child_cpu_seconds() - c0, 3)  # robust to other load on a shared CPU
            if rc != 0:
                entry["error"] = f"{stage} exited {rc}: {tail(log)}"
                print(f"gpu_check: {run}: {entry['error']}", flush=True)
                break
        if "error" not in entry:
            entry.update(summarize_run(work / safe_name(run), work / "eval" / safe_name(run) / "metrics.json"))
            print(f"gpu_check: {run}: novel PSNR {entry.get('novel_psnr')}, {entry['seconds_per_step']:.4f} s/step",
                  flush=True)  # fmt: skip
        doc["runs"][run] = entry
        write_json(out_json, doc)
    return doc


# ----------------------------------------------------------------------------------------------- the report


def parse_junit(path: Path) -> dict[str, Any]:
    """Outcome of each test case of a pytest JUnit XML: passed / failed / error / skipped, and ``passed`` overall
    (every case passed; a skip, e.g. of a CUDA test on a machine without CUDA, is not a pass)."""
    if not path.is_file():
        return {"passed": False, "cases": {}, "note": f"{path.name} absent (the tests did not run)"}
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        return {"passed": False, "cases": {}, "note": f"{path.name} unreadable ({err})"}
    cases: dict[str, str] = {}
    for case in root.iter("testcase"):
        name = f"{case.get('classname', '')}::{case.get('name', '')}"
        outcome = "passed"
        for tag in ("failure", "error", "skipped"):
            if case.find(tag) is not None:
                outcome = "failed" if tag == "failure" else tag
                break
        cases[name] = outcome
    return {"passed": bool(cases) and all(v == "passed" for v in cases.values()), "cases": cases}


def environment() -> dict[str, Any]:
    """Machine, Python, torch (and its CUDA), the GPU, gsplat; fields that cannot be read are None."""
    env: dict[str, Any] = {"python": platform.python_version(), "machine": platform.machine(),
                           "processor": cpu_name(), "cpus": os.cpu_count(),
                           "loadavg": [round(x, 2) for x in os.getloadavg()]}  # fmt: skip
    try:
        import torch

        env["torch"] = torch.__version__
        env["torch_cuda"] = torch.version.cuda
        env["cuda_available"] = torch.cuda.is_available()
        env["gpu"] = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    except ImportError:
        env["torch"] = None
    try:
        import eigs

        env["eigs_code"] = code_digest(Path(eigs.__file__).parent)
    except ImportError:
        env["eigs_code"] = None
    try:
        import gsplat

        env["gsplat"] = getattr(gsplat, "__version__", None)
    except ImportError:
        env["gsplat"] = None
    return env


def code_digest(package: Path) -> str:
    """sha256 (first 16 hex digits) over the relative paths and contents of a package's .py, .cpp and .h files: two
    reports with the same digest ran the same eigs code (a checkout's git state does not travel to a GPU machine)."""
    h = hashlib.sha256()
    for path in sorted(p for p in package.rglob("*") if p.suffix in (".py", ".cpp", ".h") and p.is_file()):
        h.update(path.relative_to(package).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def cpu_name() -> str | None:
    """The CPU model from /proc/cpuinfo (None elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def compare(runs: dict[str, dict], baseline: dict[str, dict], tolerance: float = PSNR_TOLERANCE_DB) -> dict:
    """Per run present in both: novel-view (and blur) PSNR difference this - baseline, whether it is within
    ``tolerance`` dB, and the step-time ratio baseline / this."""
    out = {}
    for run, r in runs.items():
        b = baseline.get(run)
        if b is None or "error" in r or "error" in b:
            continue
        entry: dict[str, Any] = {}
        for key in ("novel_psnr", "blur_psnr"):
            if r.get(key) is not None and b.get(key) is not None:
                entry[f"{key}_delta_db"] = r[key] - b[key]
        d = entry.get("novel_psnr_delta_db")
        entry["within_tolerance"] = None if d is None else abs(d) <= tolerance
        if r.get("seconds_per_step") and b.get("seconds_per_step"):
            entry["step_speedup"] = b["seconds_per_step"] / r["seconds_per_step"]
        out[run] = entry
    return out


def build_report(
    env: dict[str, Any],
    conformance: dict[str, Any],
    runs_doc: dict[str, Any] | None,
    *,
    gsplat_build_s: float | None = None,
    tests_rc: int | None = None,
    baseline: dict[str, Any] | None = None,
    deviations: tuple[str, ...] | list[str] | None = None,
    note: str | None = None,
) -> dict[str, Any]:
    """The gpu_check.json document: what was measured, nothing else (absent measurements are null); ``note`` is
    free text on the conditions (e.g. a shared CPU)."""
    runs = (runs_doc or {}).get("runs", {})
    for r in runs.values():
        # the training process's CPU seconds per step (start-up included): on a CPU shared with other jobs a
        # steadier figure than the wall clock's seconds_per_step
        if r.get("train_cpu_s") is not None and r.get("steps"):
            r["cpu_seconds_per_step"] = r["train_cpu_s"] / r["steps"]
    doc: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "version": 1,
        "note": note,
        "environment": env,
        "gsplat_build_s": gsplat_build_s,
        "conformance": {**conformance, "pytest_rc": tests_rc},
        "gsplat_deviations": list(deviations) if deviations is not None else None,
        "device": (runs_doc or {}).get("device"),
        "threads": (runs_doc or {}).get("threads"),
        "scene": (runs_doc or {}).get("scene"),
        "runs": runs,
        "psnr": {run: r.get("novel_psnr") for run, r in runs.items()},
        "seconds_per_step": {run: r.get("seconds_per_step") for run, r in runs.items()},
        "run_wall_s": {run: _sum_or_none(r.get("train_wall_s"), r.get("evaluate_wall_s")) for run, r in runs.items()},
    }
    if baseline is not None:
        b_env = baseline.get("environment", {})
        same = None if env.get("eigs_code") is None else env.get("eigs_code") == b_env.get("eigs_code")
        doc["baseline"] = {"device": baseline.get("device"), "processor": b_env.get("processor"),
                           "same_eigs_code": same, "comparison": compare(runs, baseline.get("runs", {}))}  # fmt: skip
    return doc


def _sum_or_none(*values: float | None) -> float | None:
    return None if any(v is None for v in values) else round(sum(values), 3)  # type: ignore[arg-type]


def merge_runs(paths: list[Path]) -> dict[str, Any] | None:
    """Several ``run`` outputs (e.g. one per run trained in parallel on the CPU) as one; None when none exists."""
    merged: dict[str, Any] | None = None
    for path in paths:
        if not path.is_file():
            continue
        doc = json.loads(path.read_text())
        if merged is None:
            merged = {k: v for k, v in doc.items() if k != "runs"} | {"runs": {}}
        elif (doc.get("device"), doc.get("threads")) != (merged.get("device"), merged.get("threads")):
            raise CheckError(f"{path}: device/threads differ from the other --runs-json files")
        merged["runs"].update(doc.get("runs", {}))
    return merged


# ----------------------------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="gpu_check.py", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bundle", help="copy one scene's artifacts and the LPIPS weights into a bundle")
    b.add_argument("--directory", type=Path, default=REPO, help="workflow directory with results/ (default: repo)")
    b.add_argument("--resources", type=Path, default=None, help="resources folder (default: DIRECTORY/resources)")
    b.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml", help="suite config (runs:)")
    b.add_argument("--scene", default="chair")
    b.add_argument("--runs", default=",".join(DEFAULT_RUNS), help="comma-separated run names of the config")
    b.add_argument("--max-mib", type=float, default=DEFAULT_MAX_MIB, help="refuse a larger bundle")
    b.add_argument("-o", "--output", type=Path, default=REPO / ".gpu_bundle")
    v = sub.add_parser("verify", help="check a bundle against its manifest")
    v.add_argument("--bundle", type=Path, required=True)
    r = sub.add_parser("run", help="train and evaluate the bundle's runs; write what was measured")
    r.add_argument("--bundle", type=Path, required=True)
    r.add_argument("--device", choices=("cpu", "cuda"), required=True)
    r.add_argument("--runs", default=",".join(DEFAULT_RUNS))
    r.add_argument("--threads", type=int, default=1, help="--threads of eigs train/evaluate (the suite's: 1)")
    r.add_argument("--work", type=Path, required=True, help="scratch folder for the run folders and logs")
    r.add_argument("-o", "--output", type=Path, required=True, help="JSON to write")
    t = sub.add_parser("report", help="assemble gpu_check.json")
    t.add_argument("--runs-json", type=Path, action="append", default=[], help="a `run` output (repeatable)")
    t.add_argument("--junit", type=Path, default=None, help="the CUDA tests' JUnit XML")
    t.add_argument("--tests-rc", type=int, default=None, help="pytest's exit status")
    t.add_argument("--gsplat-build-s", type=float, default=None, help="seconds gsplat's JIT build took")
    t.add_argument("--baseline", type=Path, default=None, help="a report to compare with (the CPU baseline)")
    t.add_argument("--note", default=None, help="free text on the conditions, kept in the JSON")
    t.add_argument("-o", "--output", type=Path, required=True)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "bundle":
            import yaml

            if not args.config.is_file():
                raise CheckError(f"--config: {args.config} does not exist")
            config = yaml.safe_load(args.config.read_text())
            resources = args.resources if args.resources is not None else args.directory / "resources"
            m = make_bundle(args.directory, resources, config, args.scene, parse_runs(args.runs), args.output,
                            args.max_mib)  # fmt: skip
            print(f"wrote {args.output}: {len(m['files'])} files, {m['bytes'] / 2**20:.1f} MiB")
        elif args.command == "verify":
            m = verify_bundle(args.bundle)
            print(f"{args.bundle}: {len(m['files'])} files verified ({m['scene']}; runs {', '.join(m['runs'])})")
        elif args.command == "run":
            doc = run_all(args.bundle, parse_runs(args.runs), args.work, args.device, args.threads, args.output)
            failed = [run for run, r in doc["runs"].items() if "error" in r]
            if failed:
                print(f"gpu_check.py run: {', '.join(failed)} failed (see {args.output})", file=sys.stderr)
                return 1
        else:
            if args.baseline is not None and not args.baseline.is_file():
                raise CheckError(f"--baseline: {args.baseline} does not exist")
            baseline = json.loads(args.baseline.read_text()) if args.baseline is not None else None
            try:
                from eigs.render._gsplat import DEVIATIONS
            except ImportError:
                DEVIATIONS = None  # noqa: N806
            conformance = parse_junit(args.junit) if args.junit is not None else {"passed": None, "cases": {}}
            doc = build_report(environment(), conformance, merge_runs(args.runs_json), tests_rc=args.tests_rc,
                               gsplat_build_s=args.gsplat_build_s, baseline=baseline,
                               deviations=DEVIATIONS, note=args.note)  # fmt: skip
            write_json(args.output, doc)
            print(f"wrote {args.output}")
    except CheckError as err:
        print(f"gpu_check.py {args.command}: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
