"""Rank correlations of eigs.tables.agreement against scipy and closed cases, and the BRISQUE/PSNR agreement table
from hand-made metrics.json files of hidden-ground-truth scenes."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from scipy import stats

from eigs.cli import main
from eigs.tables.agreement import agreement_rows, average_ranks, kendall_tau_b, spearman, to_markdown
from eigs.tables.build import SIM_LABEL, build_tables
from eigs.tables.collect import summarise
from eigs.tables.write import to_csv
from eigs.tables.write import to_markdown as to_markdown_table


def test_average_ranks_share_ties():
    assert average_ranks(np.array([3.0, 1.0, 3.0, 2.0])).tolist() == [3.5, 1.0, 3.5, 2.0]


@pytest.mark.parametrize("seed", range(20))
def test_against_scipy_with_ties(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 15))
    x = rng.integers(0, 4, n).astype(float)  # few distinct values: many ties
    y = rng.integers(0, 5, n).astype(float)
    if np.all(x == x[0]) or np.all(y == y[0]):
        return
    assert spearman(x, y)[0] == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
    assert kendall_tau_b(x, y)[0] == pytest.approx(stats.kendalltau(x, y, variant="b").statistic, abs=1e-12)


def test_closed_cases():
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert spearman(x, 10 * x) == (1.0, "") and kendall_tau_b(x, 10 * x) == (1.0, "")
    assert spearman(x, -x) == (-1.0, "") and kendall_tau_b(x, -x) == (-1.0, "")
    # one swap of 3: rho = 1 - 6*2/(3*8) = 0.5, tau = (2 - 1)/3
    assert spearman(np.array([1.0, 2, 3]), np.array([2.0, 1, 3]))[0] == pytest.approx(0.5)
    assert kendall_tau_b(np.array([1.0, 2, 3]), np.array([2.0, 1, 3]))[0] == pytest.approx(1 / 3)


@pytest.mark.parametrize(("x", "y", "why"), [([], [], "0 method(s)"), ([1.0], [2.0], "1 method(s)"),
                                             ([1.0, 1.0, 1.0], [1.0, 2.0, 3.0], "all tied"),
                                             ([1.0, 2.0], [5.0, 5.0], "all tied")])  # fmt: skip
def test_undefined_is_nan_with_a_reason(x, y, why):
    for f in (spearman, kendall_tau_b):
        v, reason = f(np.array(x), np.array(y))
        assert math.isnan(v) and reason == why


# hidden-ground-truth scenes: run -> (method, {scene: (novel PSNR, BRISQUE)}); h1 agrees, h2 is reversed, and the
# scene means tie every BRISQUE (30); the oracle, out of order on purpose, is not ranked
HIDDEN = {
    "3dgs": ("3dgs", {"h1": (20.0, 40.0), "h2": (20.0, 20.0)}),
    "e2gs": ("e2gs", {"h1": (24.0, 30.0), "h2": (24.0, 30.0)}),
    "eigs": ("eigs", {"h1": (26.0, 20.0), "h2": (26.0, 40.0)}),
    "oracle": ("oracle", {"h1": (30.0, 50.0), "h2": (30.0, 50.0)}),
}
MAPPING = {"table1": {"3dgs": "3dgs", "e2gs": "e2gs", "eigs": "eigs", "oracle": "oracle"}}


def hidden_metrics(root, run, scene, method, psnr, brisque, hidden=True, gaussians=1000):
    """A metrics.json as `eigs evaluate --hidden-ground-truth` writes it (hidden=False: a real scene, BRISQUE only)."""
    d = root / scene / "b4" / "eval" / run
    d.mkdir(parents=True)
    m = {"train": {"n": 3, "brisque": brisque, "brisque_undefined": 0},
         "path": {"n": 6, "brisque": brisque, "brisque_undefined": 0},
         "all": {"n": 9, "brisque": brisque, "brisque_undefined": 0}}  # fmt: skip
    if hidden:
        m["novel"] = {"n": 2, "psnr": psnr, "ssim_3dgs": 0.9, "ssim_skimage-gaussian": 0.9, "ssim_deblurnerf": 0.9,
                      "lpips_alex": 0.1}  # fmt: skip
        m["blur"] = dict(m["novel"])
    doc = {"format": "eigs-metrics", "version": 1, "run": run, "method": method, "scene": scene, "bins": 4,
           "run_dir": f"results/{scene}/b4/{run}", "ground_truth": hidden, "hidden_ground_truth": hidden,
           "metrics": m, "train_seconds": 10.0, "steps": 100, "n_gaussians": gaussians, "fps": 50.0}  # fmt: skip
    (d / "metrics.json").write_text(json.dumps(doc))
    return d / "metrics.json"


@pytest.fixture()
def hidden_files(tmp_path):
    return [hidden_metrics(tmp_path, run, scene, method, p, b)
            for run, (method, per) in HIDDEN.items() for scene, (p, b) in per.items()]  # fmt: skip


def test_agreement_rows_per_scene_and_overall(hidden_files):
    rows = {r.scene: r for r in agreement_rows(summarise(hidden_files))}
    assert list(rows) == ["h1", "h2", "mean over scenes", "scene means"]
    assert (rows["h1"].rho, rows["h1"].tau, rows["h1"].n_methods) == (1.0, 1.0, 3)  # oracle left out
    assert rows["h1"].methods == ("3dgs", "e2gs", "eigs")
    assert (rows["h2"].rho, rows["h2"].tau) == (-1.0, -1.0)
    assert rows["mean over scenes"].rho == 0.0 and rows["mean over scenes"].tau == 0.0
    assert rows["mean over scenes"].note == "2 of 2 scenes defined"
    sm = rows["scene means"]
    assert math.isnan(sm.rho) and math.isnan(sm.tau) and sm.note == "all tied" and sm.n_methods == 3


def test_agreement_edges_never_crash(tmp_path):
    # one Gaussian method (a field run and the oracle do not count): undefined, with the reason
    files = [hidden_metrics(tmp_path, "3dgs", "h1", "3dgs", 20.0, 30.0),
             hidden_metrics(tmp_path, "nerf", "h1", "nerf", 22.0, 25.0, gaussians=None),
             hidden_metrics(tmp_path, "oracle", "h1", "oracle", 30.0, 20.0)]  # fmt: skip
    rows = agreement_rows(summarise(files))
    assert [(r.scene, r.n_methods, r.note) for r in rows] == [
        ("h1", 1, "1 method(s)"),
        ("mean over scenes", 1, "no scene defined"),
        ("scene means", 1, "1 method(s)"),
    ]
    md = to_markdown(rows)
    assert "| h1 | 1 | – | – | 1 method(s) |" in md
    assert agreement_rows(summarise([hidden_metrics(tmp_path, "3dgs", "real", "3dgs", None, 30.0, hidden=False)])) == []


def test_table1_brisque_column_from_the_hidden_scenes(hidden_files):
    t1 = build_tables(MAPPING, summarise(hidden_files))[0]
    col = next(c for c in t1.columns if c.key == "brisque")
    assert col.label == SIM_LABEL and col.source == "brisque_sim"
    assert not any(c.key == "brisque_sim" for c in t1.columns)
    cells = {r.key: r.cells["brisque"] for r in t1.rows}
    assert cells["3dgs"].ours == pytest.approx(30.0) and cells["oracle"].ours == pytest.approx(50.0)
    assert cells["3dgs"].paper == 38.89  # the paper's real-data value stays beside ours
    assert {r.key: r.cells["psnr"].ours for r in t1.rows}["eigs"] == pytest.approx(26.0)  # same scenes' PSNR
    assert len(t1.notes) == 1 and "(h1, h2)" in t1.notes[0] and "not the paper's real recordings" in t1.notes[0]
    md = to_markdown_table(t1)
    assert SIM_LABEL + " ours (paper)" in md and t1.notes[0] in md
    header = next(csv.reader(io.StringIO(to_csv(t1))))
    assert "brisque_sim" in header and "brisque_paper" in header and "brisque" not in header


def test_real_scenes_keep_the_brisque_column(hidden_files, tmp_path):
    real = [hidden_metrics(tmp_path / "r", run, "real", run, None, 33.0, hidden=False) for run in ("3dgs", "eigs")]
    t1 = build_tables(MAPPING, summarise([*hidden_files, *real]))[0]
    col = next(c for c in t1.columns if c.key == "brisque")
    assert col.label == "BRISQUE↓" and col.source is None and not t1.notes
    eigs = next(r for r in t1.rows if r.key == "eigs")
    assert eigs.cells["brisque"].ours == pytest.approx(33.0)  # the real scene only
    assert eigs.cells["brisque_sim"].ours == pytest.approx(30.0)  # the hidden ones, in the CSV


def test_cli_writes_the_rank_table_only_with_hidden_scenes(hidden_files, tmp_path):
    out = tmp_path / "tables"
    assert main(["tables", *map(str, hidden_files), "--tables", json.dumps(MAPPING), "-o", str(out)]) == 0
    rows = list(csv.DictReader((out / "brisque_rank.csv").open()))
    assert [r["scene"] for r in rows] == ["h1", "h2", "mean over scenes", "scene means"]
    assert float(rows[0]["spearman_rho"]) == 1.0 and float(rows[1]["kendall_tau_b"]) == -1.0
    assert rows[3]["spearman_rho"] == "" and rows[3]["note"] == "all tied" and rows[0]["methods"] == "3dgs e2gs eigs"
    assert "BRISQUE against PSNR" in (out / "brisque_rank.md").read_text()
    assert "BRISQUE against PSNR" in (out / "tables.md").read_text()
    per = list(csv.DictReader((out / "per_scene.csv").open()))
    assert {r["hidden_ground_truth"] for r in per} == {"1"}
    real = [hidden_metrics(tmp_path / "r", "3dgs", "real", "3dgs", None, 33.0, hidden=False)]
    out2 = tmp_path / "tables2"
    assert main(["tables", *map(str, real), "--tables", json.dumps(MAPPING), "-o", str(out2)]) == 0
    assert not (out2 / "brisque_rank.csv").exists() and not (out2 / "brisque_rank.md").exists()
