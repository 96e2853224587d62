"""The compiled sufficient checks (synth.dataset.schema_fast): True only where jsonschema says valid."""

from __future__ import annotations

import copy
import json
import random

import jsonschema
import pytest

from synth.dataset import frame_json
from synth.dataset.schema_fast import compile_sufficient
from tests.dataset.test_frame_record import RENDERED

VALUES = [None, True, False, 0, 1, -1, 2, 1.0, 0.5, -0.0, 1e300, "", "a", "ab", "id000001_ex01_v02", [], [1],
          [1.0, 2.0], ["a", "a"], ["a", "b"], [True], {}, {"a": 1}, {"k": "v", "n": None}]

SCHEMAS = [
    {"type": "integer", "minimum": 0}, {"type": "number", "exclusiveMinimum": 0}, {"type": ["string", "null"]},
    {"const": 1}, {"enum": ["a", None, 1.0]}, {"type": "string", "pattern": "^a", "minLength": 1, "maxLength": 1},
    {"maximum": 1, "exclusiveMaximum": 2}, {"type": "array", "items": {"type": "number"}, "minItems": 1,
                                            "maxItems": 2},
    {"type": "array", "items": {"type": "string"}, "uniqueItems": True},
    {"type": "object", "required": ["a"], "properties": {"a": {"type": "integer"}}, "additionalProperties": False},
    {"type": "object", "additionalProperties": {"type": ["string", "null"]}},
    {"anyOf": [{"type": "integer", "minimum": 1}, {"type": "array", "maxItems": 1}]},
    {"$ref": "#/$defs/d"}, {"description": "anything"}, {},
]


@pytest.mark.parametrize("schema", SCHEMAS)
def test_true_only_where_jsonschema_says_valid(schema):
    defs = {"d": {"type": "object", "required": ["k"]}}
    ok = compile_sufficient(schema, defs)
    assert ok is not None
    v = jsonschema.Draft202012Validator({**schema, "$defs": defs})
    agree = 0
    for x in VALUES:
        if ok(x):
            assert v.is_valid(x), (schema, x)
        agree += ok(x) == v.is_valid(x)
    assert agree >= len(VALUES) - 3  # the check is useful, not just safe: few valid values fall back


@pytest.mark.parametrize("schema", [{"oneOf": [{"type": "null"}]}, {"type": "string", "format": "date"},
                                    {"patternProperties": {"^a": {}}}, {"$ref": "#/other"}, {"type": "tuple"},
                                    {"items": {"not": {}}}, {"const": [1]}])
def test_keywords_outside_the_set_compile_to_none(schema):
    assert compile_sufficient(schema, {}) is None


def _mutations(fj: dict, rng: random.Random, n: int):
    """Frames with one value somewhere replaced, removed or added (a fixed sequence)."""
    paths = []

    def walk(o, path):
        paths.append(path)
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, path + (k,))
        elif isinstance(o, list) and o:
            walk(o[rng.randrange(len(o))], path + (0,))

    walk(fj, ())
    for _ in range(n):
        bad = copy.deepcopy(fj)
        path = rng.choice(paths[1:])
        parent = bad
        for p in path[:-1]:
            parent = parent[p]
        op = rng.randrange(3)
        if op == 0:
            parent[path[-1]] = rng.choice(VALUES)
        elif op == 1 and isinstance(parent, dict):
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent["extra_key"] = rng.choice(VALUES)
        else:
            parent.append(rng.choice(VALUES))
        yield bad


def test_the_frame_fast_path_never_passes_what_the_schema_refuses():
    fj = json.loads(RENDERED.read_bytes())
    full = frame_json._validator()
    assert frame_json._fast_valid(fj)
    passed = refused = 0
    for bad in _mutations(fj, random.Random(3), 600):
        if frame_json._fast_valid(bad):
            assert full.is_valid(bad)
            passed += 1
        elif not full.is_valid(bad):
            refused += 1
    assert passed > 300 and refused > 100  # both kinds of mutation occur
