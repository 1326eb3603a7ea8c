"""The one validator of option dataclasses (training, radiance-field and method options; no torch).

Every option class is a frozen dataclass whose fields hold the defaults and whose :meth:`Options.problems` holds its
checks (ranges, enums, combinations). :func:`parse_options` turns a JSON mapping into one: unknown keys, types, then
the checks, each error one line naming the key (and, for unknown keys, the accepted ones).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

from eigs.errors import EigsError
from eigs.util.options import unknown_keys

O = TypeVar("O")


@dataclasses.dataclass(frozen=True)
class Options:
    """Base of the method option classes: a method without options of its own uses it as is."""

    def problems(self) -> list[str]:
        """What is wrong with these values (empty when they are valid)."""
        return []


def accepted(cls: type) -> list[str]:
    """The keys an option dataclass accepts, in field order."""
    return [f.name for f in dataclasses.fields(cls)]


def coerce(name: str, default: Any, value: Any, where: str) -> Any:
    """``value`` as the type of ``default``: an int is accepted for a float, a list of numbers for a tuple (as JSON
    gives it; tuple of floats), a bool only for a bool; anything else raises :class:`EigsError` naming ``name``."""
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or not all(
            isinstance(x, int | float) and not isinstance(x, bool) for x in value
        ):
            raise EigsError(where, f"option {name} must be a list of numbers, got {value!r}")
        return tuple(float(x) for x in value)
    want = type(default)
    if want is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, want) or isinstance(value, bool) != isinstance(default, bool):
        raise EigsError(where, f"option {name} must be {want.__name__}, got {value!r}")
    return value


def parse_options(defaults: O, values: Mapping[str, Any], where: str) -> O:
    """``defaults`` (an option dataclass instance: a method's recipe) with ``values`` over it, checked."""
    if not isinstance(values, Mapping):
        raise EigsError(where, f"expected a mapping of options, got {type(values).__name__}")
    unknown_keys(values, accepted(type(defaults)), where)
    kw = {k: coerce(k, getattr(defaults, k), v, where) for k, v in values.items()}
    opts = dataclasses.replace(defaults, **kw)  # type: ignore[type-var]
    problems = opts.problems() if isinstance(opts, Options) else []
    if problems:
        raise EigsError(where, "; ".join(problems))
    return opts


def options_json(opts: Any) -> dict[str, Any]:
    """An option dataclass as a JSON mapping (tuples as lists), in field order."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(opts).items()}
