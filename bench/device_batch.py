"""Train and evaluate many runs of the suite in parallel on a many-core machine without Snakemake (the device
machine of docs/benchmarks.md "GPU path" has 16 cores, CUDA PyTorch and no network), one thread per job
(``run --threads N``: N).

``bundle``: copy the prepared artifacts of some scenes (scene file without its raw events, EDI, SfM poses and test
cameras, init cloud: what `eigs train` and `eigs evaluate` read) into a folder with a manifest of every job's
`eigs train --config` JSON (the config files merged as Snakemake merges them).

``--prepare SCENE,...`` leaves the artifacts of those built-in scenes out of the bundle and records their
configuration instead: the machine makes them (`eigs synth`, `eigs edi`, `eigs sfm`, `eigs init`, exactly as
rules/synth.smk, edi.smk and sfm.smk call them, one thread each), first, before the jobs that read them.

``--edi-on-machine SCENE,...`` carries those scenes' scene file with its events (and their SfM poses, test cameras and
init cloud) but not their EDI file, which at 346×260 is larger than what travels to the machine: the machine runs
`eigs edi` as rules/edi.smk calls it, first, before the jobs that read it.

``run``: the scenes to prepare, then the jobs in the given order, on ``--workers`` processes, each `eigs train` then
`eigs evaluate` on the CPU, exactly as rules/train.smk and rules/evaluate.smk call them; a stage starts when the
one it reads has finished; no job starts after ``--start-until`` seconds and every stage still running at
``--deadline`` seconds is stopped (it leaves no output). Each finished job writes its run and
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
from eigs import plan  # noqa: E402

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


def compact_json(values: dict) -> str:
    """A config section as rules/common.smk ``config_json`` passes it (sorted keys, no spaces; unquoted here)."""
    return json.dumps(values, sort_keys=True, separators=(",", ":"))


def prepare_spec(config: dict, scene: str, bins: list[int]) -> dict:
    """What the machine needs to make a built-in scene's artifacts as rules/synth.smk, edi.smk and sfm.smk do: the
    scene's overrides and the edi (without bins), sfm (eigs.plan.scene_sfm) and init sections."""
    spec = (config.get("scenes") or {}).get(scene)
    if not spec or "builtin" not in spec:
        raise CheckError(f"--prepare: {scene!r} is not a built-in scene of the config")
    if plan.sfm_rule(config, scene) != "sfm":
        raise CheckError(f"--prepare: scene {scene!r}: only COLMAP SfM is prepared on the machine")
    sfm = plan.scene_sfm(config, scene)
    return {
        "builtin": spec["builtin"],
        "overrides": compact_json(spec.get("overrides") or {}),
        "bins": sorted(bins),
        "edi": edi_config(config),
        "sfm": compact_json(sfm),
        "init": compact_json(config.get("init") or {}),
    }


def edi_config(config: dict) -> str:
    """The `edi:` section without `bins`, as rules/common.smk ``edi_config`` passes it."""
    return compact_json({k: v for k, v in (config.get("edi") or {}).items() if k != "bins"})


def make_bundle(directory: Path, config: dict, jobs: list[tuple[str, str]], out: Path,
                prepare: tuple[str, ...] = (), edi_on_machine: tuple[str, ...] = ()) -> dict:  # fmt: skip
    runs = config.get("runs") or {}
    manifest: dict = {"format": FORMAT, "version": 3, "jobs": [], "files": {}, "prepare": {}, "edi": {}}
    for flag, names in (("--prepare", prepare), ("--edi-on-machine", edi_on_machine)):
        for scene in names:
            if scene not in {s for s, _ in jobs}:
                raise CheckError(f"{flag}: no job trains on {scene!r}")
    if set(prepare) & set(edi_on_machine):
        raise CheckError("a scene is both in --prepare and in --edi-on-machine")
    tmp = out.with_name(f".{out.name}.tmp")
    if tmp.exists():
        import shutil

        shutil.rmtree(tmp)
    for scene, run in jobs:
        if run not in runs:
            raise CheckError(f"--jobs: {run!r} is not a run of the config")
        b = plan.run_bins(config, run)
        manifest["jobs"].append({"scene": scene, "run": run, "bins": b, "config": train_config_json(runs[run]),
                                 "prepared": scene in prepare,
                                 "evaluate": plan.evaluate_flags(config, scene)})  # fmt: skip
        if scene in prepare:
            bins = sorted({*manifest["prepare"].get(scene, {}).get("bins", []), b})
            manifest["prepare"][scene] = prepare_spec(config, scene, bins)
            continue
        names = ["sfm/poses.h5", "sfm/test_cameras.h5", "init.ply"]
        if scene in edi_on_machine:
            bins = sorted({*manifest["edi"].get(scene, {}).get("bins", []), b})
            manifest["edi"][scene] = {"bins": bins, "edi": edi_config(config)}
        else:
            names.insert(0, "edi.h5")
        src = {f"{scene}/scene.h5": directory / "results" / scene / "scene.h5"}
        for name in names:
            src[f"{scene}/b{b}/{name}"] = directory / "results" / scene / f"b{b}" / name
        for rel, path in src.items():
            if rel in manifest["files"]:
                continue
            if not path.is_file():
                raise CheckError(f"{path}: missing; run the workflow for {scene} first")
            dst = tmp / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            if path.suffix == ".h5":
                keep_events = path.name != "scene.h5" or scene in edi_on_machine  # EDI reads them there
                copy_h5(path, dst, skip=() if keep_events else ("events",))
            else:
                dst.write_bytes(path.read_bytes())
            manifest["files"][rel] = {"sha256": sha256(dst), "bytes": dst.stat().st_size}
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / "MANIFEST.json").write_text(json.dumps(manifest, indent=2) + "\n")
    if out.exists():
        import shutil

        shutil.rmtree(out)
    os.replace(tmp, out)
    return manifest


def eigs_command() -> list[str]:
    return [sys.executable, "-m", "eigs.cli"]


def prepare_commands(work: Path, scene: str, spec: dict) -> list[tuple[str, str, list[str]]]:
    """(stage, benchmark name, command) of a prepared scene, in order: synth, then edi, sfm and init per B."""
    out = work / "results" / scene
    eigs = eigs_command()
    cmds = [("synth", scene, [*eigs, "synth", "--scene", spec["builtin"], "--config", spec["overrides"],
                              "-o", str(out / "scene.h5"), "--contact-sheet", str(out / "contact_sheet.png"),
                              "--threads", "1"])]  # fmt: skip
    for b in spec["bins"]:
        d = out / f"b{b}"
        cmds += [
            ("edi", f"{scene}_b{b}", [*eigs, "edi", str(out / "scene.h5"), "-o", str(d / "edi.h5"), "--latent-dir",
                                      str(d / "latent"), "--bins", str(b), "--config", spec["edi"], "--threads", "1"]),
            ("sfm", f"{scene}_b{b}", [*eigs, "sfm", str(out / "scene.h5"), str(d / "edi.h5"), "--latent-dir",
                                      str(d / "latent"), "-o", str(d / "sfm"), "--config", spec["sfm"],
                                      "--threads", "1"]),
            ("init", f"{scene}_b{b}", [*eigs, "init", str(d / "sfm"), "-o", str(d / "init.ply"), "--config",
                                       spec["init"]]),
        ]  # fmt: skip
    return cmds


def edi_command(bundle: Path, work: Path, scene: str, b: int, edi: str, threads: int = 1) -> list[str]:
    """`eigs edi` of a scene carried with its events, as rules/edi.smk calls it."""
    d = work / "results" / scene / f"b{b}"
    return [*eigs_command(), "edi", str(bundle / scene / "scene.h5"), "-o", str(d / "edi.h5"), "--latent-dir",
            str(d / "latent"), "--bins", str(b), "--config", edi, "--threads", str(threads)]  # fmt: skip


def job_commands(bundle: Path, resources: Path, work: Path, job: dict, edi_here: bool = False,
                 threads: int = 1) -> list[list[str]]:  # fmt: skip
    """`eigs train` then `eigs evaluate` of a job on ``threads`` threads; ``edi_here``: its EDI file was made on
    the machine."""
    s, r, b = job["scene"], job["run"], job["bins"]
    base = (work / "results" if job.get("prepared") else bundle) / s
    edi = (work / "results" / s if edi_here else base) / f"b{b}" / "edi.h5"
    run_dir = work / "results" / s / f"b{b}" / r
    metrics = work / "results" / s / f"b{b}" / "eval" / r / "metrics.json"
    eigs = eigs_command()
    return [
        [*eigs, "train", str(base / "scene.h5"), str(edi), str(base / f"b{b}" / "sfm"),
         str(base / f"b{b}" / "init.ply"), "-o", str(run_dir), "--config", job["config"], "--device", "cpu",
         "--threads", str(threads)],
        [*eigs, "evaluate", str(run_dir), str(base / "scene.h5"), str(base / f"b{b}" / "sfm"), "-o", str(metrics),
         *job.get("evaluate", []), "--resources", str(resources), "--device", "cpu", "--threads", str(threads)],
    ]  # fmt: skip


def benchmark_row(wall: float, cpu: float, max_rss_kb: int) -> str:
    hms = time.strftime("%H:%M:%S", time.gmtime(wall)).lstrip("0").lstrip(":") or "0"
    return f"{wall:.2f}\t{hms}\t{max_rss_kb / 1024:.2f}\tNA\tNA\tNA\tNA\tNA\tNA\t{cpu:.2f}\n"


def batch_tasks(bundle: Path, resources: Path, work: Path, manifest: dict, threads: int = 1) -> list[dict]:
    """Every stage to run, in priority order (the scenes to prepare first: the jobs wait for them), each with the
    index of the task it reads (``after``) and where its benchmark goes."""
    tasks: list[dict] = []
    last_of_scene: dict[str, int] = {}
    for scene, spec in (manifest.get("prepare") or {}).items():
        prev = None
        for stage, name, cmd in prepare_commands(work, scene, spec):
            tasks.append({"scene": scene, "run": None, "stage": stage, "name": name, "cmd": cmd, "after": prev})
            prev = len(tasks) - 1
        last_of_scene[scene] = prev
    edi_task: dict[tuple[str, int], int] = {}
    for scene, spec in (manifest.get("edi") or {}).items():
        for b in spec["bins"]:
            tasks.append({"scene": scene, "run": None, "stage": "edi", "name": f"{scene}_b{b}",
                          "cmd": edi_command(bundle, work, scene, b, spec["edi"], threads),
                          "after": None})  # fmt: skip
            edi_task[scene, b] = len(tasks) - 1
    for job in manifest["jobs"]:
        name = f"{job['scene']}_b{job['bins']}_{job['run']}"
        after = last_of_scene.get(job["scene"]) if job.get("prepared") else edi_task.get((job["scene"], job["bins"]))
        edi_here = (job["scene"], job["bins"]) in edi_task
        cmds = job_commands(bundle, resources, work, job, edi_here=edi_here, threads=threads)
        for stage, cmd in zip(("train", "evaluate"), cmds, strict=True):
            tasks.append({"scene": job["scene"], "run": job["run"], "stage": stage, "name": name, "cmd": cmd,
                          "after": after})  # fmt: skip
            after = len(tasks) - 1
    return tasks


def run_batch(bundle: Path, resources: Path, work: Path, workers: int, start_until: float, deadline: float,
              threads: int = 1) -> dict:  # fmt: skip
    manifest = json.loads((bundle / "MANIFEST.json").read_text())
    if manifest.get("format") != FORMAT:
        raise CheckError(f"{bundle}: not a {FORMAT} bundle")
    t0 = time.monotonic()
    tasks = batch_tasks(bundle, resources, work, manifest, threads)
    state = ["pending"] * len(tasks)  # pending / running / ok / failed / stopped / skipped
    running: dict[int, tuple[int, float, subprocess.Popen]] = {}  # pid -> (task index, start, process)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), PYTHONUNBUFFERED="1")
    (work / "logs").mkdir(parents=True, exist_ok=True)

    def start(i: int) -> None:
        t = tasks[i]
        log = open(work / "logs" / f"{t['name']}_{t['stage']}.log", "w")  # noqa: SIM115
        p = subprocess.Popen(t["cmd"], stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        log.close()
        # the Popen object is kept: one that is garbage-collected while running goes to subprocess's own reaper,
        # which would take its exit status (and its resource usage) before os.wait4 sees it
        running[p.pid] = (i, time.monotonic(), p)
        state[i] = "running"

    while True:
        now = time.monotonic() - t0
        for i, t in enumerate(tasks):  # a stage whose input failed or never came is skipped
            if state[i] == "pending" and t["after"] is not None and state[t["after"]] in ("failed", "stopped",
                                                                                           "skipped"):  # fmt: skip
                state[i] = "skipped"
        # a task is ready when what it reads is done; a job's first stage waits for --start-until, the rest not
        ready = [i for i, t in enumerate(tasks) if state[i] == "pending"
                 and (t["after"] is None or state[t["after"]] == "ok")
                 and (now < start_until or t["stage"] == "evaluate")]  # fmt: skip
        for i in ready[: max(0, workers - len(running))]:
            start(i)
        if now >= deadline:
            for pid, (i, _, _) in running.items():
                os.killpg(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                state[i] = "stopped"
            running.clear()
            break
        if not running:
            break
        pid, status, ru = os.wait4(-1, os.WNOHANG)
        if pid == 0:
            time.sleep(0.5)
            continue
        i, t_start, proc = running.pop(pid)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        t = tasks[i]
        if proc.returncode != 0:
            state[i] = "failed"
            continue
        state[i] = "ok"
        bench = work / "benchmarks" / t["stage"] / f"{t['name']}.tsv"
        bench.parent.mkdir(parents=True, exist_ok=True)
        bench.write_text(BENCH_HEADER + benchmark_row(time.monotonic() - t_start, ru.ru_utime + ru.ru_stime,
                                                      ru.ru_maxrss))  # fmt: skip
    report = {"elapsed_s": round(time.monotonic() - t0, 1), "workers": workers, "jobs": job_report(tasks, state),
              "prepared": prepare_report(tasks, state), "cpu": cpu_name() or "unknown",
              "cores": os.cpu_count(), "threads_per_job": threads}  # fmt: skip
    (work / "batch.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def job_report(tasks: list[dict], state: list[str]) -> list[dict]:
    """Per job (train + evaluate): ok, or which stage failed, was stopped, skipped or never started."""
    out = []
    for i, t in enumerate(tasks):
        if t["stage"] != "train":
            continue
        tr, ev = state[i], state[i + 1]
        if tr == "ok" and ev == "ok":
            status = "ok"
        elif tr == "pending":
            status = "not started"
        elif tr == "skipped":
            status = "skipped: its scene was not prepared"
        elif tr in ("failed", "stopped"):
            status = "train failed" if tr == "failed" else "stopped at the deadline (train)"
        else:
            status = {"failed": "evaluate failed", "stopped": "stopped at the deadline (evaluate)"}.get(ev, ev)
        out.append({"scene": t["scene"], "run": t["run"], "status": status})
    return out


def prepare_report(tasks: list[dict], state: list[str]) -> dict[str, str]:
    """Per prepared scene: ok, or its first stage that did not finish and how."""
    out: dict[str, str] = {}
    for i, t in enumerate(tasks):
        if t["run"] is None and out.get(t["scene"], "ok") == "ok":
            out[t["scene"]] = "ok" if state[i] == "ok" else f"{t['stage']} {state[i]}"
    return out


def kept(p: Path) -> bool:
    """Whether ``pack`` keeps a file: no model and no motion file (evaluation scored it into metrics.json), none of a
    prepared scene's HDF5 files and latent frames (its logs, SfM report and contact sheet stay); of the
    renders only the first blur view and its ground truth (the view the qualitative grid shows,
    eigs.tables.figures.grid_view)."""
    if p.suffix in (".ply", ".npz", ".h5") or "latent" in p.parts:
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
    b.add_argument("--prepare", default="", help="built-in scenes the machine makes itself (scene,scene,...)")
    b.add_argument("--edi-on-machine", default="", help="scenes whose EDI file the machine makes (scene,scene,...)")
    r = sub.add_parser("run")
    r.add_argument("--bundle", type=Path, required=True)
    r.add_argument("--resources", type=Path, required=True, help="folder with lpips/ (eigs evaluate --resources)")
    r.add_argument("--work", type=Path, required=True)
    r.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    r.add_argument("--start-until", type=float, default=float("inf"))
    r.add_argument("--deadline", type=float, default=float("inf"))
    r.add_argument("--threads", type=int, default=1, help="threads of each job (the prepared scenes' stages: 1)")
    r.add_argument("--pack", type=Path)
    a = ap.parse_args(argv)
    try:
        if a.cmd == "bundle":
            prepare = tuple(x.strip() for x in a.prepare.split(",") if x.strip())
            edi_here = tuple(x.strip() for x in a.edi_on_machine.split(",") if x.strip())
            m = make_bundle(a.directory, merged_config(a.config), parse_jobs(a.jobs), a.out, prepare, edi_here)
            print(f"{a.out}: {len(m['jobs'])} jobs, {sum(f['bytes'] for f in m['files'].values()) / 2**20:.1f} MiB")
        else:
            if a.workers < 1 or a.threads < 1:
                raise CheckError("--workers and --threads must be >= 1")
            rep = run_batch(a.bundle, a.resources, a.work, a.workers, a.start_until, a.deadline, a.threads)
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
