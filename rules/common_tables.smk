# Helpers of rules/evaluate.smk and rules/tables.smk (evaluation, tables, figures); needs rules/common.smk.
from eigs.tables.rows import configured_rows, table_rows


# --- evaluate -------------------------------------------------------------------------------------------------
def eval_targets():
    """metrics.json of every (run, scene) that rule train makes."""
    return [
        f"results/{scene}/b{run_bins(run)}/eval/{run}/metrics.json" for run in sorted(RUNS) for scene in run_scenes(run)
    ]


def evaluate_options(wildcards):
    """`eigs evaluate` flags of the scene (eigs.plan.evaluate_flags)."""
    return " ".join(plan.evaluate_flags(config, wildcards.scene))


# --- tables and figures ---------------------------------------------------------------------------------------
TABLE_ROWS = table_rows(config.get("tables"))
# Tables I-V always; an optional table (the ladder, config/ladder.yaml) where its runs are configured
TABLE_NAMES = list(configured_rows(config.get("tables"), RUNS))
# the BRISQUE-versus-PSNR rank agreement (eigs.tables.agreement), where an evaluated scene hides its ground truth
EXTRA_TABLES = (
    ["brisque_rank"]
    if any(plan.scene_hidden_ground_truth(config, s) for run in RUNS for s in run_scenes(run))
    else []
)


def tables_json():
    """The row mappings (defaults: eigs.tables.rows) restricted to configured runs (others -> null: paper values
    only; eigs.tables.rows.configured_rows), shell-quoted JSON."""
    values = configured_rows(config.get("tables"), RUNS)
    return shlex.quote(json.dumps(values, separators=(",", ":")))


def grid_runs():
    """Runs in the qualitative grids: Table I's rows that have a run, in the table's order (comma-separated)."""
    out = []
    for run in TABLE_ROWS["table1"].values():
        if run in RUNS and run not in out:
            out.append(run)
    return ",".join(out) or ",".join(sorted(RUNS))


def figure_scenes():
    """Scenes that get a qualitative grid: every scene some run is trained on."""
    return sorted({s for run in RUNS for s in run_scenes(run)})


def figure_inputs(wildcards):
    """The run folders' files, scene files and EDI latent folders the figures read (besides metrics.json)."""
    out = []
    for run in sorted(RUNS):
        for scene in run_scenes(run):
            b = run_bins(run)
            out += [f"results/{scene}/b{b}/{run}/{run_folder.LOG}", f"results/{scene}/b{b}/{run}/{run_folder.CONFIG}",
                    f"results/{scene}/scene.h5", f"results/{scene}/b{b}/latent"]  # fmt: skip
    return sorted(set(out))
