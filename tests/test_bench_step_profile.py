"""bench/step_profile.py's arithmetic: the profiled nodes per step and the backward's remainder."""

from __future__ import annotations

import pytest

from bench.step_profile import RASTER_NODE, node_ms, split_backward


def test_node_ms_sums_the_named_nodes_per_step():
    events = [
        ("torch::autograd::CppNode<(anonymous namespace)::RasterizeToPixels>", 30_000.0),
        ("torch::autograd::CppNode<(anonymous namespace)::ProjectGaussians>", 1_000.0),
        ("aten::mm", 5_000.0),
        ("torch::autograd::CppNode<(anonymous namespace)::RasterizeToPixels>", 6_000.0),
    ]
    assert node_ms(events, RASTER_NODE, 3) == pytest.approx(12.0)  # (30 + 6) ms over 3 steps
    assert node_ms(events, "ProjectGaussians", 2) == pytest.approx(0.5)
    assert node_ms([], RASTER_NODE, 1) == 0.0
    with pytest.raises(ValueError, match="steps"):
        node_ms(events, RASTER_NODE, 0)


def test_split_backward_is_the_remainder_and_never_negative():
    assert split_backward(220.0, 178.0, 2.0) == pytest.approx(40.0)
    assert split_backward(100.0, 99.0, 3.0) == 0.0
