"""eigs tables from hand-made metrics.json files with known answers: means over scenes, best / second best, the
oracle row excluded from the ranking, distances to the oracle, the paper's values, CSV / Markdown / LaTeX agreeing."""

from __future__ import annotations

import csv
import json
import math
import re

import pytest

from eigs.cli import main
from eigs.tables.build import COLUMNS, build_tables, rank
from eigs.tables.collect import brace_pattern, summarise
from eigs.tables.figures import pareto_front
from eigs.tables.paper import TABLES
from eigs.tables.write import fmt_time, to_csv, to_latex, to_markdown

SCENES = ("alpha", "beta")
# run -> (method, per-scene novel PSNR, SSIM, LPIPS, train seconds)
RUNS = {
    "3dgs": ("3dgs", (20.0, 21.0), (0.80, 0.82), (0.30, 0.32), 10.0),
    "e2gs": ("e2gs", (24.0, 25.0), (0.90, 0.90), (0.20, 0.22), 200.0),
    "eigs": ("eigs", (26.0, 27.0), (0.90, 0.90), (0.10, 0.12), 300.0),
    "oracle": ("oracle", (30.0, 31.0), (0.95, 0.97), (0.05, 0.05), 40.0),
}
MAPPING = {
    "table1": {"3dgs": "3dgs", "e2gs": "e2gs", "eigs": "eigs", "bad-gaussians": None, "oracle": "oracle"},
    "table2": {"3dgs": "3dgs", "ours": "eigs", "oracle": "oracle"},
    "table3": {"4": "eigs", "6": None, "8": None, "oracle": "oracle"},
}


def write_metrics(root, run, scene, method, psnr, ssim, lpips, seconds, gt=True, brisque=None, sharp=True):
    """A metrics.json; ``sharp``: with the sharpness (1 − LPIPS here, novel views; 0.5 blur views) and the coherence
    (1 − 2·LPIPS; 0.25), as runs evaluated since issue 43 have them, else without the keys, as the ledger's older
    ones."""
    d = root / scene / "b4" / "eval" / run
    d.mkdir(parents=True)
    metrics = ({"novel": {"n": 2, "psnr": psnr, "ssim_3dgs": ssim, "ssim_skimage-gaussian": ssim - 0.01,
                          "ssim_deblurnerf": ssim - 0.02, "lpips_alex": lpips},
                "blur": {"n": 2, "psnr": psnr + 1, "ssim_3dgs": ssim, "ssim_skimage-gaussian": ssim,
                         "ssim_deblurnerf": ssim, "lpips_alex": lpips}}
               if gt else {"all": {"n": 9, "brisque": brisque, "brisque_undefined": 0}})  # fmt: skip
    if gt and sharp:
        metrics["novel"].update(sharpness=1 - lpips, sharpness_undefined=0, coherence=1 - 2 * lpips,
                                coherence_undefined=0)  # fmt: skip
        metrics["blur"].update(sharpness=0.5, sharpness_undefined=0, coherence=0.25, coherence_undefined=0)
    doc = {"format": "eigs-metrics", "version": 1, "run": run, "method": method, "scene": scene, "bins": 4,
           "run_dir": f"results/{scene}/b4/{run}", "ground_truth": gt, "metrics": metrics,
           "train_seconds": seconds, "steps": 100, "n_gaussians": 1000, "fps": 50.0}  # fmt: skip
    (d / "metrics.json").write_text(json.dumps(doc))
    return d / "metrics.json"


@pytest.fixture()
def metrics_files(tmp_path):
    files = []
    for run, (method, psnr, ssim, lpips, secs) in RUNS.items():
        for i, scene in enumerate(SCENES):
            files.append(write_metrics(tmp_path, run, scene, method, psnr[i], ssim[i], lpips[i], secs))
    # one real scene (no ground truth) for two runs: BRISQUE
    files.append(write_metrics(tmp_path, "3dgs", "real", "3dgs", None, None, None, 10.0, gt=False, brisque=40.0))
    files.append(write_metrics(tmp_path, "eigs", "real", "eigs", None, None, None, 300.0, gt=False, brisque=30.0))
    return files


@pytest.fixture()
def tables(metrics_files):
    return {t.name: t for t in build_tables(MAPPING, summarise(metrics_files))}


def row(table, key):
    return next(r for r in table.rows if r.key == key)


def test_means_over_scenes_and_brisque_only_from_scenes_without_ground_truth(tables):
    t1 = tables["table1"]
    eigs = row(t1, "eigs")
    assert eigs.cells["psnr"].ours == pytest.approx(26.5)
    assert eigs.cells["lpips"].ours == pytest.approx(0.11)
    assert eigs.cells["psnr_blur"].ours == pytest.approx(27.5)
    assert eigs.cells["brisque"].ours == pytest.approx(30.0)
    assert row(t1, "e2gs").cells["brisque"].ours is None  # no real scene: no BRISQUE
    assert eigs.cells["time_s"].ours == pytest.approx(300.0) and eigs.n_scenes == 3
    assert eigs.source == "results/{alpha,beta,real}/b4/eigs"


def test_best_and_second_best_exclude_the_oracle(tables):
    t1 = tables["table1"]
    assert row(t1, "eigs").cells["psnr"].rank == 1
    assert row(t1, "e2gs").cells["psnr"].rank == 2
    assert row(t1, "3dgs").cells["psnr"].rank is None
    assert row(t1, "oracle").role == "oracle" and row(t1, "oracle").cells["psnr"].rank is None
    # LPIPS: lower is better
    assert row(t1, "eigs").cells["lpips"].rank == 1 and row(t1, "e2gs").cells["lpips"].rank == 2
    # equal SSIM as displayed (0.9000): eigs and e2gs share the best rank, 3dgs is second
    assert row(t1, "eigs").cells["ssim"].rank == 1 and row(t1, "e2gs").cells["ssim"].rank == 1
    assert row(t1, "3dgs").cells["ssim"].rank == 2
    # BRISQUE: eigs 30 best, 3dgs 40 second
    assert row(t1, "eigs").cells["brisque"].rank == 1 and row(t1, "3dgs").cells["brisque"].rank == 2


# (column, the column before it, eigs's novel and blur values from write_metrics, decimals, as Markdown prints eigs's)
BAND_COLUMNS = [("sharpness", "lpips", 0.89, 0.5, 3, "| 0.890 (–) |"),
                ("coherence", "sharpness", 0.78, 0.25, 2, "| 0.890 (–) | 0.78 (–) |")]  # fmt: skip


@pytest.mark.parametrize(("key", "after", "novel", "blur", "decimals", "shown"), BAND_COLUMNS)
def test_band_columns_are_shown_unranked_and_missing_where_a_run_predates_them(
    tables, metrics_files, tmp_path, key, after, novel, blur, decimals, shown
):
    t1 = tables["table1"]
    keys = [c.key for c in t1.columns if c.shown]
    assert keys.index(key) == keys.index(after) + 1
    eigs = row(t1, "eigs")
    assert eigs.cells[key].ours == pytest.approx(novel) and eigs.cells[f"{key}_blur"].ours == blur
    assert all(r.cells[key].rank is None and r.cells[key].paper is None for r in t1.rows)
    assert shown in to_markdown(t1)
    for name, columns in COLUMNS.items():  # every table has it: shown in Table I and the ladder, else in the CSV
        col = next(c for c in columns if c.key == key)
        assert col.shown == (name in ("table1", "ladder")) and col.decimals == decimals
    # a run evaluated before the column existed: its cell is empty, the others as before
    old = write_metrics(tmp_path / "old", "old", "alpha", "3dgs", 20.0, 0.8, 0.3, 10.0, sharp=False)
    t = {t.name: t for t in build_tables({"table1": {"3dgs": "old"}}, summarise([old]))}["table1"]
    assert row(t, "3dgs").cells[key].ours is None and row(t, "3dgs").cells["psnr"].ours == 20.0
    assert "| – (–) | – (–) |" in to_markdown(t)


def test_distance_to_oracle(tables):
    t1 = tables["table1"]
    assert row(t1, "eigs").d_oracle["psnr"] == pytest.approx(26.5 - 30.5)
    assert row(t1, "3dgs").d_oracle["lpips"] == pytest.approx(0.31 - 0.05)
    assert row(t1, "oracle").d_oracle["psnr"] == pytest.approx(0.0)


def test_paper_values_and_paper_only_rows(tables):
    t1, t3 = tables["table1"], tables["table3"]
    assert row(t1, "eigs").cells["psnr"].paper == 28.21
    assert row(t1, "e2nerf").cells["psnr"].paper == 29.56 and row(t1, "e2nerf").run is None
    # the paper's own ranking: E²NeRF best (29.56), Ours second (28.21); BRISQUE Ours best (26.08)
    assert row(t1, "e2nerf").cells["psnr"].paper_rank == 1 and row(t1, "eigs").cells["psnr"].paper_rank == 2
    assert row(t1, "eigs").cells["brisque"].paper_rank == 1
    assert row(t1, "deblurring-gs").cells["brisque"].paper_rank == 2
    r8 = row(t3, "8")
    assert r8.cells["psnr"].ours is None and r8.cells["psnr"].paper == 28.93
    assert r8.cells["time_s"].paper == 5 * 3600 + 49 * 60
    # every paper row is in its table, in the paper's order
    assert [r.key for r in t1.rows][: len(TABLES["table1"]["rows"])] == list(TABLES["table1"]["rows"])
    assert row(tables["table2"], "a").config == "+-+-"


def _strip_marks(s: str) -> str:
    return re.sub(r"\\(best|second)\{([^}]*)\}", r"\2", s.replace("**", "").replace("<u>", "").replace("</u>", ""))


def test_csv_markdown_and_latex_agree(tables):
    for t in tables.values():
        rows = list(csv.DictReader(to_csv(t).splitlines()))
        md = [line for line in to_markdown(t).splitlines() if line.startswith("| ") and "---" not in line][1:]
        tex = [line for line in to_latex(t).splitlines() if line.endswith("\\\\")][1:]
        assert len(rows) == len(md) == len(tex) == len(t.rows)
        shown = [c for c in t.columns if c.shown]
        first = 1 + (4 if t.name == "table2" else 0)
        for r, m, x in zip(rows, md, tex, strict=True):
            mcells = [c.strip() for c in m.strip("|").split(" | ")]
            xcells = [c.strip() for c in x.removesuffix("\\\\").split(" & ")]
            for j, col in enumerate(shown):
                ours, paper = r[col.key], r[f"{col.key}_paper"]
                plain = _strip_marks(mcells[first + j])
                want_ours = "–" if ours == "" else (f"{float(ours):.{col.decimals}f}" if col.decimals else None)
                if want_ours is not None:
                    assert plain.split(" (")[0] == want_ours, (t.name, r["row"], col.key, plain)
                if paper != "" and col.decimals:
                    d = col.paper_decimals if col.paper_decimals is not None else col.decimals
                    assert plain.split(" (")[1].rstrip(")") == f"{float(paper):.{d}f}"
                assert _strip_marks(xcells[first + j]).replace("--", "–") == plain
                # marks: bold / \best for rank 1, underline / \second for rank 2
                if r[f"{col.key}_rank"] == "1":
                    assert mcells[first + j].startswith("**") and xcells[first + j].startswith("\\best{")
                elif r[f"{col.key}_rank"] == "2":
                    assert mcells[first + j].startswith("<u>") and xcells[first + j].startswith("\\second{")
                else:
                    assert not mcells[first + j].startswith(("**", "<u>"))
            assert mcells[-1] == (r["source"] or "–")


def test_cli_writes_every_format(metrics_files, tmp_path):
    out = tmp_path / "tables"
    code = main(["tables", *map(str, metrics_files), "--tables", json.dumps(MAPPING), "-o", str(out)])
    assert code == 0
    for name in MAPPING:
        for ext in ("csv", "md", "tex"):
            assert (out / f"{name}.{ext}").stat().st_size > 0
    assert "Table I" in (out / "tables.md").read_text()
    per = list(csv.DictReader((out / "per_scene.csv").open()))
    assert len(per) == len(metrics_files)
    assert main(["tables", str(metrics_files[0]), "--tables", '{"table9": {}}', "-o", str(out)]) == 2


def test_helpers():
    assert fmt_time(3 * 3600 + 25 * 60) == "3h25m" and fmt_time(307) == "5m07s" and fmt_time(12.34) == "12.3s"
    assert brace_pattern(["results/a/b4/x", "results/b/b4/x"]) == "results/{a,b}/b4/x"
    assert brace_pattern(["results/a/b4/x", "results/b/b6/y"]) == "results/a/b4/x;results/b/b6/y"
    assert rank({0: 1.0, 1: 3.0, 2: 2.0, 3: None}, "higher") == {1: 1, 2: 2}
    assert rank({0: 1.0, 1: 3.0, 2: 2.0}, "lower") == {0: 1, 2: 2}
    # Pareto front over (seconds, PSNR): (1, 20) and (10, 25) and (100, 26); (50, 24) is dominated by (10, 25)
    assert pareto_front([(1, 20), (10, 25), (50, 24), (100, 26)]) == [0, 1, 3]


def test_paper_transcription_spot_checks():
    """A few cells against the paper's text (§IV-C): Table II gains and Table III times."""
    t2 = TABLES["table2"]["rows"]
    assert t2["a"]["psnr"] - t2["3dgs"]["psnr"] == pytest.approx(3.83)
    assert t2["b"]["psnr"] - t2["a"]["psnr"] == pytest.approx(1.40)
    assert t2["ours-minus"]["psnr"] - t2["a"]["psnr"] == pytest.approx(0.42)
    assert t2["ours"]["psnr"] - t2["b"]["psnr"] == pytest.approx(2.71)
    assert t2["ours"]["psnr"] - t2["ours-minus"]["psnr"] == pytest.approx(3.69)
    assert TABLES["table3"]["rows"]["8"]["psnr"] - TABLES["table3"]["rows"]["6"]["psnr"] == pytest.approx(0.12)


def test_table_rows_defaults_and_overrides():
    from eigs.tables.rows import default_rows, table_rows

    rows = table_rows({"table3": {4: "eigs", 6: None}})
    assert rows["table3"] == {"4": "eigs", "6": None}  # a table given replaces its default as a whole
    assert rows["table1"] == default_rows()["table1"]
    # every default row key is a paper row or the oracle
    for name, mapping in default_rows().items():
        assert set(mapping) - {"oracle", "edi-3dgs"} <= set(TABLES[name]["rows"]), name


def test_distance_to_oracle_is_paired_over_the_scenes_both_runs_have(metrics_files, tmp_path):
    """A run on one scene of two is compared with the oracle on that scene, not with the oracle's mean."""
    only = write_metrics(tmp_path / "extra", "partial", "alpha", "eigs", 29.0, 0.93, 0.06, 100.0)
    t1 = build_tables({"table1": {"eigs": "partial", "oracle": "oracle"}}, summarise([*metrics_files, only]))[0]
    assert row(t1, "eigs").d_oracle["psnr"] == pytest.approx(29.0 - 30.0)  # oracle on alpha: 30.0 (mean 30.5)
    assert row(t1, "eigs").d_oracle["lpips"] == pytest.approx(0.06 - 0.05)


def test_brace_pattern_keeps_absolute_paths_absolute():
    assert brace_pattern(["/tmp/x/a/run", "/tmp/x/b/run"]) == "/tmp/x/{a,b}/run"


def test_a_run_missing_on_a_scene_averages_the_scenes_it_has(metrics_files, tmp_path):
    """A run not trained on one scene (e.g. an event method on an `events: false` scene, which the workflow does not
    schedule): its cells are the means over the scenes it has, its `scenes` column says how many, its distance to the
    oracle is paired over those scenes, it is still ranked, and per_scene.csv has no row for the missing scene."""
    files = [f for f in metrics_files if f.parts[-5:-3] != ("beta", "b4") or f.parts[-2] != "e2gs"]
    assert len(files) == len(metrics_files) - 1
    t1 = build_tables({"table1": MAPPING["table1"]}, summarise(files))[0]
    e2gs = row(t1, "e2gs")
    assert e2gs.cells["psnr"].ours == pytest.approx(24.0) and e2gs.cells["lpips"].ours == pytest.approx(0.20)
    assert e2gs.n_scenes == 1 and e2gs.source == "results/alpha/b4/e2gs"
    assert e2gs.d_oracle["psnr"] == pytest.approx(24.0 - 30.0)  # the oracle on alpha, not its mean 30.5
    assert e2gs.cells["psnr"].rank == 2 and row(t1, "eigs").n_scenes == 3
    md_row = next(ln for ln in to_markdown(t1).splitlines() if ln.startswith("| E2GS"))
    assert md_row.split(" | ")[-2:] == ["1", "results/alpha/b4/e2gs |"]
    out, mapping = tmp_path / "tables", json.dumps({"table1": MAPPING["table1"]})
    assert main(["tables", *map(str, files), "--tables", mapping, "-o", str(out)]) == 0
    per = list(csv.DictReader((out / "per_scene.csv").open()))
    assert len(per) == len(files) and [r["scene"] for r in per if r["run"] == "e2gs"] == ["alpha"]


def test_the_ladder_table_exists_only_with_its_own_runs():
    from eigs.tables.rows import configured_rows

    base = ["eigs", "eigs+", "oracle", "3dgs"]
    assert "ladder" not in configured_rows(None, base)  # eigs and eigs+ alone are Tables I-V's rows
    rows = configured_rows(None, [*base, "eigs-zero"])["ladder"]
    assert rows["eigs"] == "eigs" and rows["zero"] == "eigs-zero" and rows["discrete"] is None
    assert rows["latent"] is None and rows["sharp"] == "eigs+"


def test_motion_columns_are_the_means_over_the_scenes_with_motion(tmp_path):
    files = []
    for scene, err in (("alpha", 0.2), ("beta", 0.4), ("gamma", None)):
        path = write_metrics(tmp_path, "eigs", scene, "eigs", 25.0, 0.9, 0.1, 10.0)
        doc = json.loads(path.read_text())
        doc["motion"] = None if err is None else {"displacement_relative_error": err, "displacement_cosine": 0.9}
        path.write_text(json.dumps(doc))
        files.append(path)
    s = summarise(files)["eigs"]
    assert s.values["motion_err"] == pytest.approx(0.3) and s.values["motion_cos"] == pytest.approx(0.9)
    assert math.isnan(s.values["motion_rot_deg"])  # no trajectory: no camera error
    t1 = build_tables({"table1": {"eigs": "eigs"}}, summarise(files))[0]
    assert row(t1, "eigs").cells["motion_err"].ours == pytest.approx(0.3)
