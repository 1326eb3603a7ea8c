"""eigs figures on evaluated runs of the hand-built case (tests/evaluate/fixtures.py): the three kinds of figure."""

from __future__ import annotations

import shutil

import cv2

from eigs.cli import main
from eigs.evaluate.core import evaluate_run
from tests.evaluate.conftest import resources_dir  # noqa: F401
from tests.evaluate.fixtures import make_case


def test_figures_from_two_runs(tmp_path, resources_dir):  # noqa: F811
    case = make_case(tmp_path)
    metrics = []
    for name in ("3dgs", "eigs"):
        run = tmp_path / name
        shutil.copytree(case["run"], run)
        out = tmp_path / "eval" / name / "metrics.json"
        evaluate_run(run, case["scene"], case["sfm"], out, resources=str(resources_dir))
        metrics.append(str(out))
    out = tmp_path / "figures"
    assert main(["figures", *metrics, "--grid-runs", "eigs,3dgs", "-o", str(out)]) == 0
    grid = cv2.imread(str(out / "qualitative_evalcase.png"))
    curves = cv2.imread(str(out / "curves.png"))
    pareto = cv2.imread(str(out / "pareto.png"))
    assert grid is not None and curves is not None and pareto is not None
    # the grid shows blurry input, two runs and the ground truth side by side: wider than tall
    assert grid.shape[1] > 2 * grid.shape[0]


def test_grids_are_named_by_the_workflow_scene_of_the_run_folder(tmp_path, resources_dir):  # noqa: F811
    """A run folder in the workflow's layout (results/<scene>/b<B>/<run>) whose scene file has another name (as
    config/e2nerf_blur.yaml's e2b-<scene> are built-ins made another way): the grid takes the workflow's name, which
    the figures rule expects."""
    from eigs.artifacts.run import workflow_scene

    assert workflow_scene("results/e2b-blocks/b4/eigs") == "e2b-blocks" and workflow_scene(tmp_path / "x") is None
    case = make_case(tmp_path)
    run = tmp_path / "results" / "e2b-case" / "b4" / "eigs"
    shutil.copytree(case["run"], run)
    out = tmp_path / "results" / "e2b-case" / "b4" / "eval" / "eigs" / "metrics.json"
    evaluate_run(run, case["scene"], case["sfm"], out, resources=str(resources_dir))
    figures = tmp_path / "figures"
    assert main(["figures", str(out), "-o", str(figures)]) == 0
    assert sorted(p.name for p in figures.glob("qualitative_*.png")) == ["qualitative_e2b-case.png"]
