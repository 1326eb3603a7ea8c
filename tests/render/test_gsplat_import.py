"""The GPU conformance module runs only on CUDA hosts; here, on every machine, it must at least import and reach
its gsplat requirement (a broken import there would otherwise go unnoticed until a GPU run)."""

from __future__ import annotations

import importlib
import importlib.util

import pytest


def test_gsplat_conformance_module_imports_and_requires_gsplat(monkeypatch):
    mod = importlib.import_module("test_gsplat_conformance")
    assert callable(mod.test_gsplat_matches_cpu)
    calls = []
    monkeypatch.setattr(mod, "require", lambda cond, reason: calls.append((cond, reason)), raising=False)
    mod._require_gsplat()
    assert len(calls) == 1
    assert calls[0][0] == (importlib.util.find_spec("gsplat") is not None)
    assert "gsplat" in calls[0][1]


def test_gsplat_requirement_skips_locally_and_fails_in_ci(monkeypatch):
    mod = importlib.import_module("test_gsplat_conformance")
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception):
        mod._require_gsplat()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="gsplat"):
        mod._require_gsplat()
