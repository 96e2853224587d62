"""synth.configkit: coercion by type hints, bounds and choices, TOML files and overrides,
did-you-mean, order-independent validation, the TOML writer and the reference table."""

from __future__ import annotations

import dataclasses
import math
import tomllib
import typing
from dataclasses import dataclass, field
from typing import Annotated

import pytest

from synth import configkit as ck
from synth.configkit import Bounds, Choices, ConfigError, Unordered, section
from synth.errors import SynthError


@section
class Shape:
    count: Annotated[int, Bounds(1)] = 3
    """a count"""
    scale: Annotated[float, Bounds(gt=0.0, lt=1.0)] = 0.5
    """a scale"""
    low_high: Annotated[tuple[float, float], Bounds(-10.0, 10.0)] = (0.0, 1.0)
    """an interval"""
    size: Annotated[tuple[int, int], Bounds(1, 64), Unordered()] = (4, 2)
    """a size, not an interval"""
    names: Annotated[tuple[str, ...], Choices("a", "b", "c")] = ("a",)
    """names from a list"""
    mode: Annotated[str, Choices("fast", "slow")] = "fast"
    """a mode"""
    flag: bool = False
    """a flag"""
    limit: Annotated[float | None, Bounds(0.0, 100.0)] = None
    """unset or a number"""


@section
class Limits:
    low: Annotated[float, Bounds(0.0)] = 1.0
    """lower limit"""
    high: Annotated[float, Bounds(0.0)] = 2.0
    """upper limit,
    above low"""  # a doc may wrap: white space is folded


@dataclass(frozen=True)
class Toy:
    shape: Shape = field(default_factory=Shape)
    limits: Limits = field(default_factory=Limits)


def toy_rules(cfg: Toy, where: str) -> None:
    if not cfg.limits.low < cfg.limits.high:
        raise ConfigError(f"config value limits.low = {cfg.limits.low} must be below limits.high", where, "fix it")


HINTS = typing.get_type_hints(Shape)
METADATA = {f.name: dict(f.metadata) for f in dataclasses.fields(Shape)}


def coerce(key, value):
    return ck.coerce(value, HINTS[key], f"shape.{key}", METADATA[key], "here")


@pytest.mark.parametrize("key, value, expected", [
    ("count", 1, 1),
    ("count", 10**30, 10**30),  # no upper bound
    ("limit", 3, 3.0),  # an int in a float field becomes a float
    ("scale", 0.999, 0.999),
    ("low_high", [-2, 3.5], (-2.0, 3.5)),  # lists become tuples of the element type
    ("low_high", [1, 1], (1.0, 1.0)),  # an empty-width interval is still an interval
    ("size", [64, 1], (64, 1)),  # not ordered
    ("names", [], ()),
    ("names", ["c", "a"], ("c", "a")),
    ("mode", "slow", "slow"),
    ("flag", True, True),
    ("limit", None, None),
    ("limit", 100, 100.0),
])
def test_coercion_accepts(key, value, expected):
    got = coerce(key, value)
    assert got == expected and type(got) is type(expected)
    if isinstance(got, tuple) and got:
        assert all(type(a) is type(b) for a, b in zip(got, expected))


@pytest.mark.parametrize("key, value, message", [
    ("count", 0, "shape.count = 0 must be >= 1"),
    ("count", 2.0, "is not an integer"),
    ("count", True, "is not an integer"),  # a bool is not a number here
    ("count", "3", "is not an integer"),
    ("scale", 0.0, r"is out of range \(0.0, 1.0\)"),  # both bounds exclusive
    ("scale", 1.0, r"is out of range \(0.0, 1.0\)"),
    ("scale", math.nan, "is not a finite number"),
    ("scale", math.inf, "is not a finite number"),
    ("scale", 10**400, "is not a finite number"),  # an int too large for a float
    ("scale", "x", "is not a number"),
    ("scale", False, "is not a number"),
    ("low_high", [2, 1], r"is an empty range \(low > high\)"),
    ("low_high", [0, 11], r"is out of range \[-10.0, 10.0\]"),  # bounds apply to every number
    ("low_high", [0], "is not a list of 2 values"),
    ("low_high", 3, "is not a list"),
    ("size", [0, 4], r"is out of range \[1, 64\]"),
    ("names", ["a", "d"], r"= 'd' is not allowed \(here\); choose one of a, b, c"),
    ("names", "a", "is not a list"),
    ("mode", "medium", r"is not allowed \(here\); choose one of fast, slow"),
    ("mode", 3, "is not a string"),
    ("flag", 1, "is not true or false"),
    ("limit", 101, r"is out of range \[0.0, 100.0\]"),
])
def test_coercion_refuses_with_one_line(key, value, message):
    with pytest.raises(ConfigError, match=message) as e:
        coerce(key, value)
    msg = str(e.value)
    assert msg.startswith(f"config value shape.{key} = ") and "(here)" in msg and "\n" not in msg
    assert isinstance(e.value, SynthError) and isinstance(e.value, ValueError)


def test_bounds_refuse_a_bound_given_twice():
    with pytest.raises(TypeError, match="give each bound once"):
        Bounds(0.0, 1.0, gt=0.0)
    with pytest.raises(TypeError, match="give each bound once"):
        Bounds(None, 1.0, lt=0.5)


def test_section_fields_carry_doc_bounds_and_choices():
    fields = {f.name: f for f in dataclasses.fields(Shape)}
    assert dict(fields["count"].metadata) == {"doc": "a count", "ordered": True, "range": (1, None),
                                              "open": (False, False)}
    assert fields["scale"].metadata["range"] == (0.0, 1.0) and fields["scale"].metadata["open"] == (True, True)
    assert fields["size"].metadata["ordered"] is False and fields["names"].metadata["choices"] == ("a", "b", "c")
    assert "range" not in fields["flag"].metadata and "choices" not in fields["flag"].metadata
    assert Limits.__dataclass_fields__["high"].metadata["doc"] == "upper limit, above low"
    assert HINTS["limit"] == float | None and HINTS["size"] == tuple[int, int]  # Annotated stripped
    with pytest.raises(dataclasses.FrozenInstanceError):
        Shape().count = 4  # type: ignore[misc]


def test_bounds_keep_the_numbers_as_written():
    # Limits above wrote Bounds(0.0) in Annotated[float, ...]; Bounds(0) is a different bound in
    # the tables ("range >= 0"), even though typing caches Annotated[...] by equal arguments
    @section
    class Written:
        x: Annotated[float, Bounds(0)] = 1.0
        """at least 0"""

    assert Limits.__dataclass_fields__["low"].metadata["range"] == (0.0, None)
    (low, _), = [Written.__dataclass_fields__["x"].metadata["range"]]
    assert type(low) is int and ck.meaning(Written.__dataclass_fields__["x"].metadata) == "at least 0 [range >= 0]"


def test_section_refuses_a_field_without_doc():
    with pytest.raises(TypeError, match=r"Undocumented.second has no doc"):
        @section
        class Undocumented:
            first: int = 1
            """documented"""
            second: int = 2

            def method(self):
                """not a field's doc"""


def test_section_refuses_misplaced_annotated_and_unknown_metadata():
    with pytest.raises(TypeError, match="outermost"):
        @section
        class Nested:
            x: Annotated[float, Bounds(0.0)] | None = None
            """bounds inside a union"""
    with pytest.raises(TypeError, match="unknown field metadata"):
        @section
        class Odd:
            x: Annotated[int, "positive"] = 1
            """a string is not metadata"""


def test_section_refuses_a_field_without_default():
    with pytest.raises(TypeError, match="missing 1 required"):  # a config builds its sections from defaults
        @section
        class NoDefault:
            x: int
            """no default"""


def test_section_refuses_a_default_outside_its_bounds():
    with pytest.raises(ConfigError, match=r"Bad.x = 0 must be >= 1 \(its default\)"):
        @section
        class Bad:
            x: Annotated[int, Bounds(1)] = 0
            """at least one"""


@pytest.mark.parametrize("data, message", [
    ({"shap": {"count": 2}}, "unknown config section 'shap' (x); did you mean 'shape'? known sections: shape, "
                             "limits"),
    ({"shape": {"cuont": 2}}, "unknown config key 'shape.cuont' (x); did you mean 'shape.count'?"),
    ({"shape": {"zzz": 2}}, "unknown config key 'shape.zzz' (x); known keys in [shape]: count, scale"),
    ({"shape": 3}, "config section 'shape' must be a table"),
    ([1], "config must be a table of sections"),
])
def test_apply_refuses_unknown_names(data, message):
    with pytest.raises(ConfigError) as e:
        ck.apply(Toy(), data, "x")
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


def test_apply_returns_a_new_config():
    base = Toy()
    cfg = ck.apply(base, {"shape": {"count": 7, "names": ["b"]}, "limits": {}}, "x")
    assert cfg.shape.count == 7 and cfg.shape.names == ("b",) and cfg.shape.mode == "fast"
    assert base == Toy() and cfg.limits == base.limits


@pytest.mark.parametrize("item, expected", [
    ("shape.count=4", {"shape": {"count": 4}}),
    ("shape.mode=slow", {"shape": {"mode": "slow"}}),  # a bare word is a string
    ('shape.mode="slow"', {"shape": {"mode": "slow"}}),
    ("shape.low_high=[-1, 2.5]", {"shape": {"low_high": [-1, 2.5]}}),
    (" shape . count = 4 ", {"shape": {"count": 4}}),
    ("shape.mode=a=b", {"shape": {"mode": "a=b"}}),
])
def test_parse_override(item, expected):
    assert ck.parse_override(item) == expected


@pytest.mark.parametrize("item", ["count=3", "shape.count", "nothing"])
def test_parse_override_refuses(item):
    with pytest.raises(ConfigError, match="bad override"):
        ck.parse_override(item)


def test_parse_override_refuses_deep_nesting():
    with pytest.raises(ConfigError, match="nested too deeply"):
        ck.parse_override("shape.names=" + "[" * 100_000 + "]" * 100_000)


def test_read_toml_refusals(tmp_path):
    def refused(path, message):
        with pytest.raises(ConfigError, match=message) as e:
            ck.read_toml(path)
        assert "\n" not in str(e.value) and str(path) in str(e.value)

    refused(tmp_path / "missing.toml", "config file not found")
    refused(tmp_path, "config file not found")  # a directory
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"[shape]\ncount = \xff\n")
    refused(bad, r"not UTF-8 text \(byte 16\)")
    bad.write_text("[shape\n")
    refused(bad, "not valid TOML")
    bad.write_text("v = " + "[" * 100_000 + "]" * 100_000 + "\n")
    refused(bad, "nested too deeply")
    bad.write_bytes(b"#" * (ck.MAX_FILE_BYTES + 1))
    refused(bad, "larger than")
    refused(str(tmp_path / "a\0b.toml"), "config file not found")  # a NUL byte in the path


def test_load_applies_every_override_then_checks_once(tmp_path):
    # low=5 alone breaks low < high, high=6 alone is fine: both orders must give the same config
    a = ck.load(Toy(), None, ["limits.low=5", "limits.high=6"], toy_rules)
    b = ck.load(Toy(), None, ["limits.high=6", "limits.low=5"], toy_rules)
    assert a == b and (a.limits.low, a.limits.high) == (5.0, 6.0)
    # a file whose state breaks the rule is fine when an override repairs it
    f = tmp_path / "c.toml"
    f.write_text("[limits]\nlow = 5.0\n")
    assert ck.load(Toy(), f, ["limits.high=9"], toy_rules).limits == Limits(5.0, 9.0)
    # the final state is judged, once, naming where it came from
    with pytest.raises(ConfigError, match=r"limits.low = 7.0 must be below limits.high \(--set\)"):
        ck.load(Toy(), None, ["limits.high=6", "limits.low=7"], toy_rules)
    with pytest.raises(ConfigError, match=rf"limits.low = 5.0 must be below limits.high \({f}\)"):
        ck.load(Toy(), f, (), toy_rules)
    # a bad value is refused naming the override it came from
    with pytest.raises(ConfigError, match=r"\(--set shape.count=0\)"):
        ck.load(Toy(), None, ["limits.low=5", "shape.count=0"], toy_rules)


def test_load_checks_a_base_built_in_code():
    with pytest.raises(ConfigError, match="shape.count = 0 must be >= 1"):
        ck.load(Toy(shape=Shape(count=0)), None, (), None)


@pytest.mark.parametrize("text", ["plain", 'quote " and \\ backslash', "tab\tnew\nline", "ünïcödé ☃ 🙂",
                                  "del \x7f bell \x07", "'single'", ""])
def test_toml_writer_round_trips(text):
    cfg = ck.apply(Toy(), {"shape": {"mode": "fast", "limit": 3.25}}, "x")
    cfg = dataclasses.replace(cfg, shape=dataclasses.replace(cfg.shape, mode=text))  # bypass choices
    back = tomllib.loads(ck.to_toml(cfg))
    assert back["shape"]["mode"] == text and back["shape"]["limit"] == 3.25
    assert back == ck.to_dict(cfg)


def test_to_dict_drops_unset_values_unless_asked():
    assert "limit" not in ck.to_dict(Toy())["shape"]
    d = ck.to_dict(Toy(), drop_none=False)
    assert d["shape"]["limit"] is None and d["shape"]["low_high"] == [0.0, 1.0]


def test_reference_and_markdown():
    rows = ck.reference({"default": Toy(), "other": ck.apply(Toy(), {"shape": {"count": 9}}, "x")})
    by_key = {r[0]: r for r in rows}
    assert len(rows) == 10 and list(by_key)[:2] == ["shape.count", "shape.scale"]
    assert by_key["shape.count"] == ("shape.count", "int", "3", "9", "a count [range >= 1]")
    assert by_key["shape.scale"][-1] == "a scale [range 0.0 < x < 1.0]"
    assert by_key["shape.low_high"][-1] == "an interval [range -10.0 .. 10.0]"
    assert by_key["shape.names"][1:3] == ("tuple[str, ...]", "['a']")
    assert by_key["shape.names"][-1] == "names from a list [one of: a, b, c]"
    assert by_key["shape.limit"][1:3] == ("float | None", "unset")
    md = ck.markdown({"default": Toy()}).splitlines()
    assert md[:2] == ["| key | type | default | meaning |", "|---|---|---|---|"]
    assert "| `shape.limit` | float \\| None | `unset` | unset or a number [range 0.0 .. 100.0] |" in md
    assert all(line.count("|") - line.count("\\|") == 5 for line in md)
