"""Options of every stage, built one way (no heavy imports): a frozen dataclass subclass of :class:`Options` whose
fields hold the defaults, whose field metadata name the keys that take one of a few values (:func:`choice`) and the
fields that are run control rather than config keys (:func:`run_control`), and whose :meth:`Options.problems` holds
its other checks. :func:`parse_options` is the one validator: unknown keys (naming the accepted ones), types, the
choices, then ``problems()``, each error one :class:`EigsError` line naming the key. The CLI of a stage and the
workflow's planning check (:mod:`eigs.plan`) both go through it (``Cls.from_dict``).

    defaults (dataclass)  ←  ``--config`` JSON (the rule's config section)  ←  explicit flags

Flags therefore have no defaults of their own (argparse ``default=None``: "not given"). A field whose default is
itself an :class:`Options` instance (``SfmConfig.colmap``) is nested: its config keys sit beside the parent's in the
config section, and :func:`parse_options` routes them to it.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Any, ClassVar, TypeVar

from eigs.errors import EigsError

O = TypeVar("O")
_CHOICES = "choices"  # field metadata: the values the key takes
_RUN_CONTROL = "run_control"  # field metadata: not a key of the config section


def choice(default: Any, values: Iterable[Any]) -> Any:
    """A dataclass field with ``default`` that takes one of ``values`` (checked by :func:`parse_options`)."""
    return dataclasses.field(default=default, metadata={_CHOICES: tuple(values)})


def run_control(default: Any) -> Any:
    """A dataclass field with ``default`` that the command line sets but a config section does not."""
    return dataclasses.field(default=default, metadata={_RUN_CONTROL: True})


@dataclasses.dataclass(frozen=True)
class Options:
    """Base of every options dataclass (frozen; fields hold the defaults). A class without options of its own (a
    method that has none) uses it as is."""

    kind: ClassVar[str] = "option"  # what an unknown key is called in an error ("unknown option(s) …")

    def problems(self) -> list[str]:
        """What is wrong with these values beyond types and choices (empty when they are valid)."""
        return []

    @classmethod
    def from_dict(cls: type[O], values: Mapping[str, Any], where: str = "options") -> O:
        """The class's defaults with ``values`` (config keys, nested ones flat) over them, checked."""
        return parse_options(cls(), values, where)


def _nested(cls: type) -> dict[str, type]:
    """Fields of ``cls`` whose default is an :class:`Options` instance: name → its class."""
    out = {}
    for f in dataclasses.fields(cls):
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if isinstance(default, Options):
            out[f.name] = type(default)
    return out


def accepted(cls: type) -> list[str]:
    """The config keys of an options dataclass, in field order (a nested class's after the parent's own)."""
    nested = _nested(cls)
    own = [f.name for f in dataclasses.fields(cls) if f.name not in nested and not f.metadata.get(_RUN_CONTROL)]
    return own + [k for sub in nested.values() for k in accepted(sub)]


def choices(cls: type) -> dict[str, tuple]:
    """The config keys of ``cls`` (nested ones included) that take one of a few values: key → those values."""
    out = {f.name: f.metadata[_CHOICES] for f in dataclasses.fields(cls) if _CHOICES in f.metadata}
    for sub in _nested(cls).values():
        out.update(choices(sub))
    return out


def _hint_types(cls: type, name: str) -> tuple[type, ...]:
    """The non-None types the annotation of field ``name`` allows (``int | None`` → ``(int,)``)."""
    hint = typing.get_type_hints(cls)[name]
    args = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    return tuple(typing.get_origin(a) or a for a in args if a is not type(None))


def coerce(name: str, default: Any, value: Any, where: str, allowed: tuple[type, ...] = ()) -> Any:
    """``value`` as the type of ``default`` (or, for a None default, one of ``allowed``: None is accepted then): an int
    is accepted for a float, a list of numbers for a tuple (as JSON gives it; tuple of floats), a bool only for a bool;
    anything else raises :class:`EigsError` naming ``name``."""
    if default is None:
        if value is None:
            return None
        for want in allowed:
            try:
                return coerce(name, want(), value, where)
            except EigsError:
                continue
        names = " or ".join(t.__name__ for t in allowed)
        raise EigsError(where, f"option {name} must be {names} or null, got {value!r}")
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
    """``defaults`` (an options dataclass instance: a class's defaults or a method's recipe) with ``values`` over it,
    checked: unknown keys, types, choices, then ``problems()``; each error one :class:`EigsError` line."""
    if not isinstance(values, Mapping):
        raise EigsError(where, f"expected a mapping of options, got {type(values).__name__}")
    cls = type(defaults)
    unknown_keys(values, accepted(cls), where, getattr(cls, "kind", "option"))
    nested = _nested(cls)
    own = {k: v for k, v in values.items() if not any(k in accepted(sub) for sub in nested.values())}
    kw: dict[str, Any] = {}
    for name, sub in nested.items():
        part = {k: v for k, v in values.items() if k in accepted(sub)}
        if part:
            kw[name] = parse_options(getattr(defaults, name), part, where)
    for key, value in own.items():
        default = getattr(defaults, key)
        allowed = _hint_types(cls, key) if default is None else ()
        kw[key] = coerce(key, default, value, where, allowed)
        accepted_values = choices(cls).get(key)
        if accepted_values is not None and kw[key] not in accepted_values:
            raise EigsError(f"{where}: {key}", f"{value!r} is not one of {', '.join(map(str, accepted_values))}")
    opts = dataclasses.replace(defaults, **kw)  # type: ignore[type-var]
    problems = opts.problems() if isinstance(opts, Options) else []
    if problems:
        raise EigsError(where, "; ".join(problems))
    return opts


def options_json(opts: Any) -> dict[str, Any]:
    """An options dataclass as a JSON mapping (tuples as lists), in field order."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(opts).items()}


def parse_config_json(text: str | None, option: str = "--config") -> dict[str, Any]:
    """A JSON object from the command line (``None`` or blank: ``{}``); :class:`EigsError` otherwise."""
    if not text or not text.strip():
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


def from_command_line(cls: type[O], config: str | None, given: Mapping[str, Any], option: str = "--config") -> O:
    """A stage CLI's options: ``cls``'s defaults ← the ``--config`` JSON ← the flags ``given`` (None: not given)."""
    values = {**parse_config_json(config, option), **{k: v for k, v in given.items() if v is not None}}
    return cls.from_dict(values, option)  # type: ignore[attr-defined]


def check_section(where: str, values: Any, cls: type[Options]) -> None:
    """A stage's config section as the workflow plans it (``None``: not set), through the validator its CLI uses."""
    if values is not None:
        if not isinstance(values, Mapping):
            raise EigsError(where, f"expected a mapping of option → value, got {values!r}")
        cls.from_dict(values, where)


def flags(args: Any, keys: Iterable[str]) -> dict[str, Any]:
    """The values of ``args`` (an argparse namespace) named ``keys`` (None when not given)."""
    return {k: getattr(args, k, None) for k in keys}
