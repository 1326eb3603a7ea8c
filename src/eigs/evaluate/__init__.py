"""Evaluation of a trained run (``eigs evaluate``): renders at the test cameras (synthetic scenes) or at the
training views' reference poses and a render path (scenes without ground truth), 8-bit quantised and saved, scored with
:mod:`eigs.metrics` into ``metrics.json`` and a per-image CSV. See docs/evaluation.md."""
