"""Frozen records read from and written to a plan's JSON objects: the checks every record's
``from_json`` makes (one SynthError line naming the key and where it is) and the field-by-field
reading and writing that the plan records share (:mod:`synth.assets.params`,
:mod:`synth.plan.records`)."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, Mapping

from synth.errors import SynthError

FIX = "re-run 'synth plan' (see docs/plan-format.md)"


def spec_error(what: str, where: str) -> SynthError:
    return SynthError(f"bad shard spec: {what}", where, FIX)


def as_object(d: Any, where: str) -> Mapping:
    if not isinstance(d, Mapping):
        raise spec_error(f"expected an object, got {type(d).__name__}", where)
    return d


def required(d: Mapping, key: str, types: type | tuple[type, ...], where: str):
    """``d[key]``, refused when missing or not of ``types`` (bool is never a number)."""
    if key not in d:
        raise spec_error(f"'{key}' is missing", where)
    v = d[key]
    numeric = types in (int, float, (int, float))
    if (numeric and isinstance(v, bool)) or not isinstance(v, types):
        raise spec_error(f"'{key}' is {type(v).__name__} {str(v)[:40]}, not {getattr(types, '__name__', types)}", where)
    return v


#: reads one field of a record from its JSON object: ``reader(d, key, where)``, refusing a bad value
Reader = typing.Callable[[Mapping, str, str], Any]


def of_type(types: type | tuple[type, ...]) -> Reader:
    """A :data:`Reader` of a value of ``types`` (:func:`required`)."""
    return lambda d, key, where: required(d, key, types, where)


def record_from_json(cls: type, d: Any, where: str, readers: Mapping[str, Reader],
                     keys: Mapping[str, str] | None = None):
    """The frozen record ``cls`` read from the JSON object ``d``: each field of ``readers`` (in
    that order, so the first bad key is the one reported) by its reader, from the key of the
    field's name (``keys``: field -> another key)."""
    d = as_object(d, where)
    keys = keys or {}
    return cls(**{name: read(d, keys.get(name, name), where) for name, read in readers.items()})


def record_to_json(record, keys: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A record's fields as a JSON object in their declared order (``keys``: field -> another key)."""
    keys = keys or {}
    return {keys.get(f.name, f.name): getattr(record, f.name) for f in dataclasses.fields(record)}
