"""Stage options from one source: the stage's options dataclass holds every default; a rule passes its config
section as one JSON object (``--config JSON``); flags given on the command line win over it.

    defaults (dataclass)  ←  ``--config`` JSON (the rule's config section)  ←  explicit flags

Flags therefore have no defaults of their own (argparse ``default=None``: "not given").
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

from eigs.errors import EigsError


def parse_config_json(text: str | None, option: str = "--config") -> dict[str, Any]:
    """A JSON object from the command line (``None`` or empty: ``{}``); :class:`EigsError` otherwise."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise EigsError(option, f"not valid JSON ({err})") from None
    if not isinstance(value, dict):
        raise EigsError(option, "must be a JSON object of option → value")
    return value


def unknown_keys(values: Mapping[Any, Any], keys: list[str], where: str, what: str = "option") -> None:
    """Raise :class:`EigsError` naming the keys of ``values`` not among ``keys``, and the accepted ones."""
    unknown = sorted(map(str, set(values) - set(keys)))
    if unknown:
        raise EigsError(where, f"unknown {what}(s) {', '.join(unknown)}; accepted: {', '.join(keys) or 'none'}")


def merge(keys: Iterable[str], section: Mapping[str, Any], given: Mapping[str, Any], option: str = "--config"):
    """``section`` (checked against ``keys``) updated by the entries of ``given`` that are not None."""
    unknown_keys(section, sorted(set(keys)), option)
    return {**section, **{k: v for k, v in given.items() if v is not None}}


def check_section(where: str, values: Any, keys: Iterable[str], choices: Mapping[str, Iterable[Any]]) -> None:
    """A stage's config section as the workflow plans it: a mapping of known keys whose ``choices`` keys take one of
    their values; each error one :class:`EigsError` line naming the key and the accepted keys or values."""
    if values is None:
        return
    if not isinstance(values, Mapping):
        raise EigsError(where, f"expected a mapping of option → value, got {values!r}")
    unknown_keys(values, list(keys), where)
    for key, accepted in choices.items():
        accepted = tuple(accepted)
        if key in values and values[key] not in accepted:
            raise EigsError(f"{where}: {key}", f"{values[key]!r} is not one of {', '.join(map(str, accepted))}")


def flags(args: Any, keys: Iterable[str]) -> dict[str, Any]:
    """The values of ``args`` (an argparse namespace) named ``keys`` (None when not given)."""
    return {k: getattr(args, k, None) for k in keys}
