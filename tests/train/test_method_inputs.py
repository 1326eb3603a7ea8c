"""Which methods need events: the catalog's ``needs_events`` (eigs.train.catalog, what the workflow reads) follows
from each method's code: an event loss or a latent-frame term in its recipe, or EDI latent frames (or the EDI
artifact's event counts) as what it trains on."""

from __future__ import annotations

import inspect
import logging
from unittest import mock

import numpy as np
import pytest

from eigs.train.catalog import METHODS, event_methods, method_class
from eigs.train.field.methods import ImageField
from eigs.train.gaussian.camera_motion import TrajectoryMethod
from eigs.train.gaussian.deblur import MultiRender
from eigs.train.gaussian.methods import ImageMethod
from eigs.train.resolve import warn_without_events


def reads_events_by_code(name: str) -> bool:
    """Whether a method's default recipe reads events, decided from its class and recipe."""
    cls = method_class(name)
    if issubclass(cls, (MultiRender, TrajectoryMethod)):
        o = METHODS[name].defaults()
        return (
            o.event_loss != "none" or getattr(o, "latent_weight", 0) > 0 or getattr(o, "blur_target", "") == "discrete"
        )
    if issubclass(cls, (ImageMethod, ImageField)):  # what samples() trains on: the latent frames or not
        data = mock.MagicMock()
        data.valid = np.ones((2, 3), bool)
        data.has_sharp_train = np.ones(2, bool)
        method = mock.MagicMock(data=data, views=np.arange(2))
        cls.samples(method)
        return "latent" in data._mock_children
    return "data.edi" in inspect.getsource(cls)  # the other field methods: the event counts of the EDI artifact


def test_the_event_methods():
    assert event_methods() == {"eigs", "eigs-b", "e2gs", "besplat", "evagaussians", "edi-3dgs", "edi-nerf", "e2nerf"}


@pytest.mark.parametrize("name", sorted(METHODS))
def test_the_set_follows_from_the_code(name):
    assert METHODS[name].needs_events == reads_events_by_code(name), name


def test_training_on_an_edi_without_events_warns(caplog):
    data = mock.MagicMock()
    data.edi.event_count = np.zeros(3, np.int64)
    with caplog.at_level(logging.WARNING, logger="eigs.train"):
        warn_without_events("eigs", True, data)
        warn_without_events("3dgs", False, data)
        data.edi.event_count = np.array([0, 5, 0])
        warn_without_events("eigs", True, data)
    assert [r.getMessage().split(",")[0] for r in caplog.records] == ["method eigs reads events"]
