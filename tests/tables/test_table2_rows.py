"""Table II is the paper's ablation: its rows, as configured in the default suite, resolve to the same training
configuration except for the parts the paper ablates (the event loss and the motion-consistency loss). No row may
receive event information through another path (e.g. a blur target or latent-frame term built from the events)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from eigs.tables.rows import configured_rows
from eigs.train.config import TrainConfig
from eigs.train.resolve import method_options
from eigs.util.options import options_json

REPO = Path(__file__).resolve().parents[2]
ABLATED = {"event_loss", "consistency"}  # the paper's Table II switches (L_event, L_consis); L_blur and ADE are on
# what each row must have for the paper's marks (CONFIG in eigs.tables.paper): (L_event on, L_consis on)
EXPECTED = {"a": (False, False), "b": (True, False), "ours-minus": (False, True), "ours": (True, True)}


def resolved(spec: dict[str, Any]) -> dict[str, Any]:
    """Every option a run trains with: the TrainConfig fields and the method's options with their defaults."""
    cfg = TrainConfig.from_dict({"method": spec["method"], **spec.get("options", {})})
    method = options_json(method_options(cfg))
    train = {k: v for k, v in cfg.to_dict().items() if k not in ("method", "method_options")}
    return {**{f"train.{k}": v for k, v in train.items()}, **method, "bins": spec.get("bins")}


def table2_runs(config: dict[str, Any]) -> dict[str, dict[str, Any]]:
    rows = configured_rows(config.get("tables"), config["runs"])["table2"]
    return {row: resolved(config["runs"][rows[row]]) for row in EXPECTED if rows.get(row)}


def differing(a: dict[str, Any], b: dict[str, Any]) -> set[str]:
    return {k for k in set(a) | set(b) if a.get(k) != b.get(k)}


def check(config: dict[str, Any]) -> None:
    runs = table2_runs(config)
    assert set(runs) == set(EXPECTED), f"Table II rows without a configured run: {set(EXPECTED) - set(runs)}"
    for row, (event, consis) in EXPECTED.items():
        o = runs[row]
        assert (o["event_loss"] != "none") == event and bool(o["consistency"]) == consis, row
        assert o["ade"], f"row {row} has no ADE"
        assert o["blur_target"] == "blurry" and float(o["latent_weight"]) == 0.0, (
            f"row {row} gets event information outside the event loss (blur_target / latent_weight)"
        )
    names = list(runs)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            extra = differing(runs[a], runs[b]) - ABLATED
            assert not extra, f"Table II rows {a} and {b} differ in {sorted(extra)}, not only in the ablated losses"


def test_the_default_suite_table2_rows_differ_only_in_the_ablated_losses():
    check(yaml.safe_load((REPO / "config" / "config.yaml").read_text()))


def test_the_check_fails_on_a_row_that_differs_in_anything_else():
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    run = configured_rows(config.get("tables"), config["runs"])["table2"]["b"]
    config["runs"][run]["options"]["method_options"]["lambda_p"] = 0.02
    with pytest.raises(AssertionError, match="lambda_p"):
        check(config)
    config = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    config["runs"][run]["options"]["method_options"]["blur_target"] = "discrete"  # events through the target
    with pytest.raises(AssertionError, match="event information"):
        check(config)
