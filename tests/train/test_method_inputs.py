"""Which methods need events: the light set the workflow reads (eigs.train.method_inputs.EVENT_METHODS) is what every
registered method class says (``needs_events``), and it follows from each method's code: an event loss or a
latent-frame term in its recipe, or EDI latent frames (or the EDI artifact's event counts) as what it trains on."""

from __future__ import annotations

import inspect
import logging
from unittest import mock

import numpy as np
import pytest

from eigs.train.camera_motion import TrajectoryMethod
from eigs.train.deblur import MultiRender
from eigs.train.field_methods import FIELD_REGISTRY, ImageField
from eigs.train.method_inputs import EVENT_METHODS, needs_events
from eigs.train.methods import REGISTRY, ImageMethod, method_names, method_needs_events, warn_without_events


def reads_events_by_code(cls) -> bool:
    """Whether a method's default recipe reads events, decided from its class."""
    if issubclass(cls, (MultiRender, TrajectoryMethod)):
        o = cls.OPTIONS
        return o["event_loss"] != "none" or float(o.get("latent_weight", 0)) > 0 or o.get("blur_target") == "discrete"
    if issubclass(cls, (ImageMethod, ImageField)):  # what samples() trains on: the latent frames or not
        data = mock.MagicMock()
        data.valid = np.ones((2, 3), bool)
        data.has_sharp_train = np.ones(2, bool)
        method = mock.MagicMock(data=data, views=np.arange(2))
        cls.samples(method)
        return "latent" in data._mock_children
    return "data.edi" in inspect.getsource(cls)  # the other field methods: the event counts of the EDI artifact


def test_every_method_class_reads_the_light_set():
    assert EVENT_METHODS <= set(method_names())
    for name in method_names():
        assert method_needs_events(name) == needs_events(name) == (name in EVENT_METHODS), name


@pytest.mark.parametrize("name", sorted({*REGISTRY, *FIELD_REGISTRY}))
def test_the_set_follows_from_the_code(name):
    method_names()  # registers every method
    cls = REGISTRY.get(name) or FIELD_REGISTRY[name]
    assert cls.needs_events == reads_events_by_code(cls), name


def test_training_on_an_edi_without_events_warns(caplog):
    data = mock.MagicMock()
    data.edi.event_count = np.zeros(3, np.int64)
    with caplog.at_level(logging.WARNING, logger="eigs.train"):
        warn_without_events("eigs", True, data)
        warn_without_events("3dgs", False, data)
        data.edi.event_count = np.array([0, 5, 0])
        warn_without_events("eigs", True, data)
    assert [r.getMessage().split(",")[0] for r in caplog.records] == ["method eigs reads events"]
