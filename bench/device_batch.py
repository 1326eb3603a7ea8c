"""Train and evaluate many runs of the suite in parallel on a many-core machine without Snakemake (the device
machine of docs/benchmarks.md "GPU path" has 16 cores, CUDA PyTorch and no network), one thread per job.

``bundle``: copy the prepared artifacts of some scenes (scene file without its raw events, EDI, SfM poses and test
cameras, init cloud: what `eigs train` and `eigs evaluate` read) into a folder with a manifest of every job's
`eigs train --config` JSON (the config files merged as Snakemake merges them).

``run``: the jobs in the given order on ``--workers`` processes, each `eigs train` then `eigs evaluate` on the CPU,
exactly as rules/train.smk and rules/evaluate.smk call them; no job starts after ``--start-until`` seconds and every
job still running at ``--deadline`` seconds is stopped (it leaves no output). Each finished job writes its run and
evaluation folders under ``WORK/results/<scene>/b<B>/`` and a benchmark file in Snakemake's format (wall seconds and
CPU seconds of the process and its children, from ``wait4``) under ``WORK/benchmarks/``, so the suite ledger
(bench/suite_ledger.py ``save``) takes them like a workflow directory's; ``--pack FILE`` writes them (without the
models) to one tar.gz.

Run: ``python3 bench/device_batch.py bundle --directory . --config config/config.yaml config/ladder.yaml
--scene chair --scene tree --jobs chair:eigs,tree:eigs-a -o .batch`` here, then on the machine
``python3 bench/device_batch.py run --bundle .batch --resources .gpu_bundle/resources --work /tmp/batch
--workers 14 --start-until 420 --deadline 540 --pack $OUT/batch.tgz``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.gpu_check import CheckError, copy_h5, cpu_name, sha256, train_config_json  # noqa: E402
from bench.schedule import merge_configs  # noqa: E402

FORMAT = "eigs-device-batch"
BENCH_HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"


def merged_config(paths: list[Path]) -> dict:
    """The config files merged as Snakemake merges --configfile arguments (bench.schedule.merge_configs)."""
    return merge_configs([yaml.safe_load(Path(p).read_text()) for p in paths])


def parse_jobs(text: str) -> list[tuple[str, str]]:
    """``scene:run,scene:run`` → ordered (scene, run) pairs, no duplicates."""
    jobs = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        scene, sep, run = item.partition(":")
        if not sep or not scene or not run:
            raise CheckError(f"--jobs: {item!r} is not scene:run")
        jobs.append((scene, run))
    if len(set(jobs)) != len(jobs):
        raise CheckError("--jobs: a job is named twice")
    return jobs


def make_bundle(directory: Path, config: dict, jobs: list[tuple[str, str]], out: Path) -> dict:
    runs = config.get("runs") or {}
    bins_default = int((config.get("edi") or {}).get("bins", [4])[0])
    manifest: dict = {"format": FORMAT, "version": 1, "jobs": [], "files": {}}
    tmp = out.with_name(f".{out.name}.tmp")
    if tmp.exists():
        import shutil

        shutil.rmtree(tmp)
    for scene, run in jobs:
        if run not in runs:
            raise CheckError(f"--jobs: {run!r} is not a run of the config")
        b = int(runs[run].get("bins", bins_default))
        manifest["jobs"].append({"scene": scene, "run": run, "bins": b, "config": train_config_json(runs[run])})
        src = {f"{scene}/scene.h5": directory / "results" / scene / "scene.h5"}
        for name in ("edi.h5", "sfm/poses.h5", "sfm/test_cameras.h5", "init.ply"):
            src[f"{scene}/b{b}/{name}"] = directory / "results" / scene / f"b{b}" / name
        for rel, path in src.items():
            if rel in manifest["files"]:
                continue
            if not path.is_file():
                raise CheckError(f"{path}: missing; run the workflow for {scene} first")
            dst = tmp / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            if path.suffix == ".h5":
                copy_h5(path, dst, skip=("events",) if path.name == "scene.h5" else ())
            else:
                dst.write_bytes(path.read_bytes())
            manifest["files"][rel] = {"sha256": sha256(dst), "bytes": dst.stat().st_size}
    (tmp / "MANIFEST.json").write_text(json.dumps(manifest, indent=2) + "\n")
    if out.exists():
        import shutil

        shutil.rmtree(out)
    os.replace(tmp, out)
    return manifest


def job_commands(bundle: Path, resources: Path, work: Path, job: dict) -> list[list[str]]:
    s, r, b = job["scene"], job["run"], job["bins"]
    base = bundle / s
    run_dir = work / "results" / s / f"b{b}" / r
    metrics = work / "results" / s / f"b{b}" / "eval" / r / "metrics.json"
    eigs = [sys.executable, "-m", "eigs.cli"]
    return [
        [*eigs, "train", str(base / "scene.h5"), str(base / f"b{b}" / "edi.h5"), str(base / f"b{b}" / "sfm"),
         str(base / f"b{b}" / "init.ply"), "-o", str(run_dir), "--config", job["config"], "--device", "cpu",
         "--threads", "1"],
        [*eigs, "evaluate", str(run_dir), str(base / "scene.h5"), str(base / f"b{b}" / "sfm"), "-o", str(metrics),
         "--resources", str(resources), "--device", "cpu", "--threads", "1"],
    ]  # fmt: skip


def benchmark_row(wall: float, cpu: float, max_rss_kb: int) -> str:
    hms = time.strftime("%H:%M:%S", time.gmtime(wall)).lstrip("0").lstrip(":") or "0"
    return (f"{wall:.2f}\t{hms}\t{max_rss_kb / 1024:.2f}\tNA\tNA\tNA\tNA\tNA\tNA\t{cpu:.2f}\n")


def run_batch(bundle: Path, resources: Path, work: Path, workers: int, start_until: float, deadline: float) -> dict:
    manifest = json.loads((bundle / "MANIFEST.json").read_text())
    if manifest.get("format") != FORMAT:
        raise CheckError(f"{bundle}: not a {FORMAT} bundle")
    t0 = time.monotonic()
    pending = list(manifest["jobs"])
    running: dict[int, dict] = {}  # pid -> job state
    done: list[dict] = []
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    (work / "logs").mkdir(parents=True, exist_ok=True)

    def start(job: dict, stage: int) -> None:
        cmd = job_commands(bundle, resources, work, job)[stage]
        name = f"{job['scene']}_b{job['bins']}_{job['run']}"
        log = open(work / "logs" / f"{name}_{('train', 'evaluate')[stage]}.log", "w")  # noqa: SIM115
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        log.close()
        # the Popen object is kept: one that is garbage-collected while running goes to subprocess's own reaper,
        # which would take its exit status (and its resource usage) before os.wait4 sees it
        running[p.pid] = {**job, "stage": stage, "t": time.monotonic(), "name": name, "proc": p}

    while pending or running:
        now = time.monotonic() - t0
        while pending and len(running) < workers and now < start_until:
            start(pending.pop(0), 0)
        if now >= deadline:
            for pid, st in running.items():
                os.killpg(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                stage = ("train", "evaluate")[st["stage"]]
                done.append({"scene": st["scene"], "run": st["run"], "status": f"stopped at the deadline ({stage})"})
            running.clear()
            break
        if not running:
            break
        pid, status, ru = os.wait4(-1, os.WNOHANG)
        if pid == 0:
            time.sleep(0.5)
            continue
        st = running.pop(pid)
        st["proc"].returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        wall = time.monotonic() - st["t"]
        stage = ("train", "evaluate")[st["stage"]]
        bench = work / "benchmarks" / stage / f"{st['name']}.tsv"
        bench.parent.mkdir(parents=True, exist_ok=True)
        if os.waitstatus_to_exitcode(status) != 0:
            done.append({"scene": st["scene"], "run": st["run"], "status": f"{stage} failed"})
            continue
        bench.write_text(BENCH_HEADER + benchmark_row(wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss))
        if st["stage"] == 0:
            start({k: st[k] for k in ("scene", "run", "bins", "config")}, 1)
        else:
            done.append({"scene": st["scene"], "run": st["run"], "status": "ok", "evaluate_s": round(wall, 1)})
    not_started = [{"scene": j["scene"], "run": j["run"], "status": "not started"} for j in pending]
    report = {"elapsed_s": round(time.monotonic() - t0, 1), "workers": workers, "jobs": done + not_started,
              "cpu": cpu_name() or "unknown", "cores": os.cpu_count()}  # fmt: skip
    (work / "batch.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def kept(p: Path) -> bool:
    """Whether ``pack`` keeps a file: no model and no motion file (evaluation scored it into metrics.json); of the
    renders only the first blur view and its ground truth (the view the qualitative grid shows,
    eigs.tables.figures.grid_view)."""
    if p.suffix in (".ply", ".npz"):
        return False
    if "renders" in p.parts:
        i = p.parts.index("renders")
        if len(p.parts) != i + 3 or p.parts[i + 1] not in ("blur", "gt_blur"):
            return False
        first = min(q.name for q in (p.parents[1] / "blur").glob("*.png"))
        return p.name == first
    return True


def pack(work: Path, out: Path) -> None:
    """The small outputs of the finished jobs (:func:`kept`) into ``out`` (tar.gz)."""
    with tarfile.open(out, "w:gz") as tar:
        for p in sorted(work.rglob("*")):
            if p.is_file() and kept(p):
                tar.add(p, arcname=str(p.relative_to(work)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("bundle")
    b.add_argument("--directory", type=Path, default=Path("."))
    b.add_argument("--config", type=Path, nargs="+", required=True)
    b.add_argument("--jobs", required=True, help="scene:run,scene:run,... in the order they should run")
    b.add_argument("-o", "--out", type=Path, required=True)
    r = sub.add_parser("run")
    r.add_argument("--bundle", type=Path, required=True)
    r.add_argument("--resources", type=Path, required=True, help="folder with lpips/ (eigs evaluate --resources)")
    r.add_argument("--work", type=Path, required=True)
    r.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    r.add_argument("--start-until", type=float, default=float("inf"))
    r.add_argument("--deadline", type=float, default=float("inf"))
    r.add_argument("--pack", type=Path)
    a = ap.parse_args(argv)
    try:
        if a.cmd == "bundle":
            m = make_bundle(a.directory, merged_config(a.config), parse_jobs(a.jobs), a.out)
            print(f"{a.out}: {len(m['jobs'])} jobs, {sum(f['bytes'] for f in m['files'].values()) / 2**20:.1f} MiB")
        else:
            if a.workers < 1:
                raise CheckError("--workers must be >= 1")
            rep = run_batch(a.bundle, a.resources, a.work, a.workers, a.start_until, a.deadline)
            ok = sum(j["status"] == "ok" for j in rep["jobs"])
            print(f"device_batch: {ok} of {len(rep['jobs'])} jobs finished in {rep['elapsed_s']} s on {rep['cpu']}")
            if a.pack:
                pack(a.work, a.pack)
    except CheckError as err:
        print(f"device_batch: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
