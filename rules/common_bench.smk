# Helpers of rules/bench.smk (the `bench` target); needs rules/common.smk and rules/common_tables.smk.
BENCH_DIR = os.path.normpath(os.path.join(workflow.basedir, "..", "bench"))
BENCH_QUICK = bool(config["bench_quick"])  # default: the schema
# Threads of every bench job: the machine's 2 cores of the measured sections, so that with `--cores 2` (make bench)
# no two timings overlap (workflow.cores would need --cores, which cluster runs do not set).
BENCH_THREADS = 2
# Arguments of each bench/<name>.py: (full, quick). Quick: few scenes, sizes and repeats, minutes in all.
BENCH_ARGS = {
    "metrics": ("", "--quick"),
    "ingest": ("", "--events 2000000"),
    "synth": ("", "toy"),
    "edi": ("--work results/bench/work/edi", "--work results/bench/work/edi --scenes toy --bins 2,4"),
    "sfm": ("--given --work results/bench/work/sfm",
            "--given --work results/bench/work/sfm --scenes blocks --bins 2 --scaling-scene ''"),  # fmt: skip
    "rasterizer": ("", "--quick"),
}
BENCH_SCRIPTS = sorted(n for n in BENCH_ARGS if n != "metrics")  # the bench_script jobs (metrics has its own rule)
BENCH_DOC = "results/bench/benchmarks.md" if BENCH_QUICK else "docs/benchmarks.md"
BENCH_FIGURES = "results/bench/figures" if BENCH_QUICK else "docs/figures"


def bench_args(name):
    return BENCH_ARGS[name][1 if BENCH_QUICK else 0]


def bench_train_scene():
    """The scene the training-step benchmark trains on (config `bench_train_scene`)."""
    if "bench_train_scene" in config:
        return config["bench_train_scene"]
    return "chair" if "chair" in SCENES else (BUILTIN_SCENES or ALL_SCENES)[0]


def bench_facts():
    """Job counts of this config for the skips table (bench/report.py): training and upstream jobs, scenes whose SfM
    uses given poses, scenes configured with `events: false`, per run named by a table row: its method, the number
    of rows naming it and its `steps` option (null: the TrainConfig default), and the same for every run whose method
    needs events (not scheduled on `events: false` scenes)."""
    named = [run for rows in TABLE_ROWS.values() for run in rows.values() if run in RUNS]

    def run_facts(r):
        return {"method": RUNS[r]["method"], "steps": RUNS[r].get("options", {}).get("steps")}

    return config_json({
        "train_jobs": sum(len(run_scenes(r)) for r in RUNS),
        "upstream_jobs": len(ALL_SCENES) * len(edi_bins()),
        "sfm_given": len(SFM_GIVEN_SCENES),
        "frames_only": len(FRAMES_ONLY_SCENES),
        "table_runs": {r: {**run_facts(r), "rows": named.count(r)} for r in sorted(set(named))},
        "event_runs": {r: run_facts(r) for r in sorted(RUNS) if plan.needs_events(RUNS[r]["method"])},
    })  # fmt: skip
