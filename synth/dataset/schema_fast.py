"""Sufficient checks compiled from a JSON Schema, for the frame JSON's hot path.

:func:`compile_sufficient` turns a schema built from a small set of keywords into a plain
Python function ``ok(x)`` with one promise: ``ok(x)`` True means ``x`` is valid under the
schema as jsonschema (draft 2020-12) judges it. False promises nothing: the caller then asks
jsonschema, which decides and says why. A schema with any keyword outside the set compiles to
None. The checks are stricter than the schema where that keeps them simple (an ``integer``
must be a Python ``int``, a ``const`` must have the constant's own type), never looser.

jsonschema takes about 100 us to walk a frame's camera or image object; the compiled check
takes a few.
"""

from __future__ import annotations

import re
from typing import Callable

Check = Callable[[object], bool]

#: keywords that constrain nothing (``$defs`` is reached through ``$ref``; ``$id`` only names the document)
_ANNOTATIONS = frozenset({"description", "title", "$comment", "examples", "default", "$schema", "$id", "$defs"})
_SCALARS = (str, int, float, bool, type(None))
_TYPES: dict[str, tuple[type, ...]] = {"object": (dict,), "array": (list,), "string": (str,), "integer": (int,),
                                       "number": (int, float), "boolean": (bool,), "null": (type(None),)}
_NUMBER = (int, float)


def _always(x) -> bool:
    return True


def compile_sufficient(schema, defs: dict | None = None, _depth: int = 0) -> Check | None:
    """``ok(x)`` True only when ``x`` is valid under ``schema`` (``$ref``s resolve to
    ``#/$defs/NAME`` in ``defs``); None when the schema uses a keyword not handled here."""
    if _depth > 32:
        return None
    if schema is True or schema == {}:
        return _always
    if not isinstance(schema, dict):
        return None
    keys = set(schema) - _ANNOTATIONS
    parts: list[Check] = []
    for key in sorted(keys):
        part = _keyword(key, schema[key], schema, defs or {}, _depth)
        if part is None:
            return None
        if part is not _always:
            parts.append(part)
    if not parts:
        return _always
    if len(parts) == 1:
        return parts[0]
    return lambda x: all(p(x) for p in parts)


def _keyword(key: str, value, schema: dict, defs: dict, depth: int) -> Check | None:
    sub = lambda s: compile_sufficient(s, defs, depth + 1)  # noqa: E731
    if key == "type":
        names = [value] if isinstance(value, str) else value
        if not isinstance(names, list) or not names or any(n not in _TYPES for n in names):
            return None
        allowed = frozenset(t for n in names for t in _TYPES[n])
        return lambda x: type(x) in allowed  # bool is its own type: never an integer or number here
    if key in ("const", "enum"):
        values = [value] if key == "const" else value
        if not isinstance(values, list) or any(type(v) not in _SCALARS for v in values):
            return None
        pairs = frozenset((type(v), v) for v in values)
        return lambda x: type(x) in _SCALARS and (type(x), x) in pairs
    if key in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        if type(value) not in _NUMBER:
            return None
        cmp = {"minimum": lambda x: x >= value, "maximum": lambda x: x <= value,
               "exclusiveMinimum": lambda x: x > value, "exclusiveMaximum": lambda x: x < value}[key]
        return lambda x: type(x) not in _NUMBER or cmp(x)  # applies to numbers only, as in the schema
    if key in ("minLength", "maxLength", "pattern"):
        if key == "pattern":
            if not isinstance(value, str):
                return None
            rx = re.compile(value)
            return lambda x: type(x) is not str or rx.search(x) is not None
        if type(value) is not int:
            return None
        if key == "minLength":
            return lambda x: type(x) is not str or len(x) >= value
        return lambda x: type(x) is not str or len(x) <= value
    if key in ("minItems", "maxItems"):
        if type(value) is not int:
            return None
        if key == "minItems":
            return lambda x: type(x) is not list or len(x) >= value
        return lambda x: type(x) is not list or len(x) <= value
    if key == "uniqueItems":
        if value is False:
            return _always
        # strings only: two equal strings are the same JSON value and nothing else is
        return lambda x: type(x) is not list or (all(type(v) is str for v in x) and len(set(x)) == len(x))
    if key == "items":
        each = sub(value)
        if each is None:
            return None
        return lambda x: type(x) is not list or all(map(each, x))
    if key == "required":
        if not isinstance(value, list) or any(type(v) is not str for v in value):
            return None
        names = tuple(value)
        return lambda x: type(x) is not dict or all(n in x for n in names)
    if key == "properties":
        if not isinstance(value, dict):
            return None
        props = {name: sub(s) for name, s in value.items()}
        if any(c is None for c in props.values()):
            return None
        props = {n: c for n, c in props.items() if c is not _always}
        return lambda x: type(x) is not dict or all(c(x[n]) for n, c in props.items() if n in x)
    if key == "additionalProperties":
        rest = sub(value) if value is not False else None
        if value is not False and rest is None:
            return None
        named = schema.get("properties", {})
        if not isinstance(named, dict):
            return None
        known = frozenset(named)
        if value is False:
            return lambda x: type(x) is not dict or all(k in known for k in x)
        return lambda x: type(x) is not dict or all(rest(v) for k, v in x.items() if k not in known)
    if key == "anyOf":
        if not isinstance(value, list) or not value:
            return None
        branches = [sub(s) for s in value]
        if any(b is None for b in branches):
            return None
        return lambda x: any(b(x) for b in branches)
    if key == "$ref":
        if not isinstance(value, str) or not value.startswith("#/$defs/") or value[8:] not in defs:
            return None
        return sub(defs[value[8:]])
    return None
