"""The suite's scheduling list (tests/conftest.py HEAVIEST_FIRST) names test files that exist, once each, and the
README's test command keeps xdist from reordering them."""

from __future__ import annotations

from pathlib import Path

from tests.conftest import HEAVIEST_FIRST

REPO = Path(__file__).resolve().parents[1]


def test_heaviest_first_names_existing_test_files():
    missing = [name for name in HEAVIEST_FIRST if not (REPO / name).is_file()]
    assert not missing, f"tests/conftest.py HEAVIEST_FIRST names files that do not exist: {missing}"
    assert len(set(HEAVIEST_FIRST)) == len(HEAVIEST_FIRST)


def test_make_test_keeps_the_collected_order():
    recipe = (REPO / "Makefile").read_text().split("\ntest:", 1)[1].split("\n\n", 1)[0]
    assert "--dist loadfile --no-loadscope-reorder" in recipe
