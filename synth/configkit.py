'''Typed dataclass configs with documented fields, presets, TOML files and ``--set`` overrides.

A *config* is a frozen dataclass whose fields are *sections*; a section is a class decorated
with :func:`section`, each field a plain annotated default with its one-line doc right under it
(an attribute docstring) and its bounds and choices as ``Annotated`` metadata (:class:`Bounds`,
:class:`Choices`, :class:`Unordered`), often through an alias::

    Size = Annotated[int, Bounds(1)]

    @section
    class TrainConfig:
        steps: Size = 1_000_000
        """total optimisation steps (the learning-rate schedule spans them)"""

Bounds are inclusive (``Bounds(low, high)``, None = unbounded) unless given as ``gt`` / ``lt``
(exclusive), on every number of a tuple; a numeric pair is an interval unless ``Unordered()``.
This is the one home of the machinery of the renderer's config (:mod:`synth.config`) and the prior's
(:mod:`prior.config`, :mod:`prior.train.config`, :mod:`prior.fit.config`): :func:`coerce`,
:func:`read_toml`, :func:`parse_override`, :func:`apply` (each failure one line), :func:`load`
(base <- TOML file <- every ``--set`` in order, *then* every check once, so their order never
matters), :func:`to_dict`, :func:`to_toml`, :func:`reference` and :func:`markdown`.
'''

from __future__ import annotations

import ast
import dataclasses
import difflib
import functools
import inspect
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Callable

from synth.errors import SynthError

#: config files larger than this are refused before parsing (a config is a few KiB)
MAX_FILE_BYTES = 1 << 20


class ConfigError(SynthError, ValueError):
    """A refused config value: one line for the CLI (exit 2), a ValueError for library callers."""


@dataclasses.dataclass(frozen=True, eq=False)  # typing caches Annotated[] by equal args: 0 == 0.0
class Bounds:
    """Bounds of a number (of each number of a tuple): inclusive low / high, or exclusive gt / lt."""

    low: float | None = None
    high: float | None = None
    gt: float | None = dataclasses.field(default=None, kw_only=True)
    lt: float | None = dataclasses.field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        if (self.gt is not None and self.low is not None) or (self.lt is not None and self.high is not None):
            raise TypeError("give each bound once: low/high or gt=/lt=")


class Choices:
    """The allowed values of a field (of every element, for a tuple): ``Choices("vgg", "alex")``."""

    def __init__(self, *values: Any) -> None:
        self.values = values


class Unordered:
    """A numeric pair that is not a ``[low, high]`` interval (e.g. a resolution)."""


def _metadata(doc: str, extras: tuple, where: str) -> dict[str, Any]:
    """The field metadata the checks and tables read: doc, ordered, range/open, choices."""
    md: dict[str, Any] = {"doc": doc, "ordered": not any(isinstance(x, Unordered) for x in extras)}
    for x in extras:
        if isinstance(x, Bounds) and (x.low, x.high, x.gt, x.lt) != (None,) * 4:
            md["range"] = (x.gt if x.gt is not None else x.low, x.lt if x.lt is not None else x.high)
            md["open"] = (x.gt is not None, x.lt is not None)
        elif isinstance(x, Choices):
            md["choices"] = x.values
        elif not isinstance(x, (Bounds, Unordered)):
            raise TypeError(f"{where}: unknown field metadata {x!r} (use Bounds, Choices or Unordered)")
    return md


@functools.cache
def _class_bodies(path: str) -> dict[str, list[ast.stmt]]:
    """Qualified name -> body of every class in a source file (each file parsed once)."""
    bodies: dict[str, list[ast.stmt]] = {}

    def walk(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                bodies.setdefault(prefix + child.name, child.body)
                walk(child, f"{prefix}{child.name}.")
            else:
                local = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
                walk(child, f"{prefix}{child.name}.<locals>." if local else prefix)

    walk(ast.parse(Path(path).read_bytes()), "")
    return bodies


def _attribute_docs(cls: type) -> dict[str, str]:
    """Field name -> the string right under its declaration in the class source, white space folded."""
    body = _class_bodies(inspect.getsourcefile(cls))[cls.__qualname__]
    return {a.target.id: " ".join(b.value.value.split()) for a, b in zip(body, body[1:])
            if isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name)
            and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str)}


def section(cls: type) -> type:
    """``cls`` as a frozen dataclass, each field's doc, bounds and choices in its metadata. ``Annotated``
    goes outermost; a field without a doc or a default, or a default out of bounds, fails here."""
    docs, hints = _attribute_docs(cls), typing.get_type_hints(cls, include_extras=True)
    for name in cls.__dict__.get("__annotations__", {}):
        where, hint = f"{cls.__qualname__}.{name}", hints[name]
        if name not in docs:
            raise TypeError(f"{where} has no doc: write a one-line docstring right under it")
        annotated = typing.get_origin(hint) is typing.Annotated
        if "Annotated[" in repr(typing.get_args(hint)[0] if annotated else hint):
            raise TypeError(f"{where}: put Annotated[...] outermost in the type")
        md = _metadata(docs[name], hint.__metadata__ if annotated else (), where)
        setattr(cls, name, dataclasses.field(default=cls.__dict__.get(name, dataclasses.MISSING), metadata=md))
    cls = dataclasses.dataclass(frozen=True)(cls)
    check_section(cls(), cls.__qualname__, "its default")  # a section is built from its defaults alone
    return cls


def sections(config_cls: type) -> dict[str, type]:
    """Section name -> section dataclass, in declaration order."""
    hints = typing.get_type_hints(config_cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(config_cls)}


# --------------------------------------------------------------------------- values


def type_name(tp) -> str:
    """``int``, ``float | None``, ``tuple[float, float]``, ``tuple[str, ...]``."""
    return tp.__name__ if isinstance(tp, type) else str(tp).replace("typing.", "")


def _interval(md: dict) -> tuple[str, str, str]:
    """The bounds of a field as (doc note, what is wrong, what to do): ``range 0 .. 1``,
    ``range >= 1``, ``range 0 < x <= 1``."""
    (lo, hi), (lo_open, hi_open) = md["range"], md["open"]
    if lo is not None and hi is not None:
        if not (lo_open or hi_open):
            return f"range {lo} .. {hi}", f"is out of range [{lo}, {hi}]", f"choose a value between {lo} and {hi}"
        cond = f"{lo} {'<' if lo_open else '<='} x {'<' if hi_open else '<='} {hi}"
        interval = f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
        return f"range {cond}", f"is out of range {interval}", f"choose a value in {interval}"
    cond = f"{'>' if lo_open else '>='} {lo}" if lo is not None else f"{'<' if hi_open else '<='} {hi}"
    return f"range {cond}", f"must be {cond}", f"choose a value {cond}"


def _in_bounds(value, md: dict) -> bool:
    (lo, hi), (lo_open, hi_open) = md["range"], md["open"]
    return ((lo is None or (value > lo if lo_open else value >= lo))
            and (hi is None or (value < hi if hi_open else value <= hi)))


def coerce(value: Any, tp, key: str, md: dict | None = None, where: str | None = None) -> Any:
    """``value`` checked against the type hint ``tp`` and the field metadata ``md`` (bounds,
    choices, ordered pairs); returns the typed value (lists become tuples, ints in a float
    field become floats). Raises :class:`ConfigError` naming ``key``."""
    md = md or {}
    origin = typing.get_origin(tp)

    def bad(what: str, fix: str):
        raise ConfigError(f"config value {key} = {value!r} {what}", where, fix)

    if origin in (typing.Union, types.UnionType):  # ``float | None``; ``bool | str`` with Choices(.., "auto")
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for a in (a for a in args if a is not type(None)):
            try:
                return coerce(value, a, key, md, where)
            except ConfigError as e:
                errors.append(e)
        if "choices" in md and len(errors) > 1:
            bad("is not allowed", f"choose one of {_choices(md['choices'])}")
        raise errors[0]
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            bad("is not a list", f"write it as a list, e.g. {key}=[...]")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(v, args[0], key, md, where) for v in value)
        if len(value) != len(args):
            bad(f"is not a list of {len(args)} values", f"write [{', '.join(type_name(a) for a in args)}]")
        items = tuple(coerce(v, a, key, md, where) for v, a in zip(value, args))
        if len(args) == 2 and md.get("ordered", True) and args[0] in (int, float) and items[0] > items[1]:
            bad("is an empty range (low > high)", "give [low, high] with low <= high")
        return items
    if tp is bool:
        if not isinstance(value, bool):
            bad("is not true or false", "write true or false")
    elif tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            bad("is not an integer", "write a whole number")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            bad("is not a number", "write a number")
        try:
            value = float(value)
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            bad("is not a finite number", "write a finite number")
    elif tp is str:
        if not isinstance(value, str):
            bad("is not a string", "write it in quotes")
    if "range" in md and tp in (int, float) and not _in_bounds(value, md):
        bad(*_interval(md)[1:])
    if "choices" in md and not any(value == c and type(value) is type(c) for c in md["choices"]):
        bad("is not allowed", f"choose one of {_choices(md['choices'])}")
    return value


def _choices(values) -> str:
    """Allowed values as they are written in TOML: ``false, true, auto``."""
    return ", ".join(str(v).lower() if isinstance(v, bool) else str(v) for v in values)


def check(cfg: Any, where: str | None) -> None:
    """Every field of every section of ``cfg`` (however it was built) checked by :func:`coerce`."""
    for name in sections(type(cfg)):
        check_section(getattr(cfg, name), name, where)


def check_section(section: Any, name: str, where: str | None) -> None:
    """Every field of one section (named ``name`` in messages) checked by :func:`coerce`."""
    hints = typing.get_type_hints(type(section))
    for f in dataclasses.fields(section):
        coerce(getattr(section, f.name), hints[f.name], f"{name}.{f.name}", dict(f.metadata), where)


# --------------------------------------------------------------------------- reading


def _did_you_mean(name: str, known: list[str], prefix: str = "") -> str:
    near = difflib.get_close_matches(name, known, n=1)
    return f"did you mean '{prefix}{near[0]}'? " if near else ""


def apply(cfg: Any, data: Any, where: str) -> Any:
    """A copy of ``cfg`` with ``{section: {key: value}}`` applied, each value coerced and checked
    on its own (cross-field rules are the caller's, after the last override)."""
    known = sections(type(cfg))
    if not isinstance(data, dict):
        raise ConfigError("config must be a table of sections", where, f"sections: {', '.join(known)}")
    out = {name: getattr(cfg, name) for name in known}
    for sec, values in data.items():
        if sec not in known:
            raise ConfigError(f"unknown config section '{sec}'", where,
                              f"{_did_you_mean(sec, list(known))}known sections: {', '.join(known)}")
        if not isinstance(values, dict):
            raise ConfigError(f"config section '{sec}' must be a table", where, f"write [{sec}] and key = value lines")
        fields = {f.name: f for f in dataclasses.fields(known[sec])}
        hints = typing.get_type_hints(known[sec])
        kw = {}
        for k, v in values.items():
            if k not in fields:
                raise ConfigError(f"unknown config key '{sec}.{k}'", where,
                                  f"{_did_you_mean(k, list(fields), f'{sec}.')}known keys in [{sec}]: "
                                  f"{', '.join(fields)}")
            kw[k] = coerce(v, hints[k], f"{sec}.{k}", dict(fields[k].metadata), where)
        out[sec] = dataclasses.replace(out[sec], **kw)
    return dataclasses.replace(cfg, **out)


def parse_override(item: str, example: str | None = None) -> dict[str, dict[str, Any]]:
    """``section.key=value`` -> ``{section: {key: value}}``; the value is read as TOML, else
    taken as a bare string (``--set render.preset=ci``). ``example``: shown in the refusal."""
    lhs, eq, rhs = item.partition("=")
    if not eq or "." not in lhs:
        raise ConfigError(f"bad override '{item}'", "--set",
                          "write --set section.key=value" + (f", e.g. {example}" if example else ""))
    sec, key = (s.strip() for s in lhs.split(".", 1))
    try:
        value = tomllib.loads(f"v = {rhs.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = rhs.strip()
    except RecursionError:
        raise ConfigError("override value is nested too deeply", f"--set {sec}.{key}", "write a flat value") from None
    return {sec: {key: value}}


def read_toml(path: str | Path) -> dict[str, Any]:
    """A TOML config file as a dict; a missing, unreadable, oversized, non-UTF-8 or malformed
    file is one :class:`ConfigError` line."""
    p = Path(path)
    where = str(p)
    try:
        found = p.is_file()
        size = p.stat().st_size if found else 0
        raw = p.read_bytes() if found and size <= MAX_FILE_BYTES else b""
    except (OSError, ValueError) as err:  # ValueError: a NUL byte in the path
        raise ConfigError(f"config file cannot be read: {getattr(err, 'strerror', None) or err}", where,
                          "check the --config path and its permissions") from None
    if not found:
        raise ConfigError("config file not found", where, "check the --config path")
    if size > MAX_FILE_BYTES:
        raise ConfigError(f"config file is larger than {MAX_FILE_BYTES} bytes", where,
                          "pass a TOML config file (a few KiB)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"config file is not UTF-8 text (byte {err.start})", where,
                          "save it as UTF-8 TOML") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"config file is not valid TOML: {err}", where, "fix the syntax") from None
    except RecursionError:
        raise ConfigError("config file is not valid TOML: nested too deeply", where, "fix the syntax") from None


def _example(cfg: Any) -> str:
    """``section.key=value`` of the config's first key, for refusals of malformed overrides."""
    sec = next(iter(sections(type(cfg))))
    f = dataclasses.fields(getattr(cfg, sec))[0]
    return f"{sec}.{f.name}={_scalar_toml(getattr(getattr(cfg, sec), f.name))}"


def load(base: Any, path: str | Path | None = None, overrides=(),
         cross_check: Callable[[Any, str], None] | None = None, where: str | None = None) -> Any:
    """``base`` <- TOML file <- every ``--set`` override, in order; *then* every field and the
    cross-field rules ``cross_check(cfg, where)`` are checked once, so no intermediate state is
    judged and the order of overrides does not matter. ``where`` names the final state in
    errors (default: ``--set`` if there are overrides, else the file)."""
    cfg = base
    if path is not None:
        cfg = apply(cfg, read_toml(path), str(path))
    for item in overrides:
        cfg = apply(cfg, parse_override(item, _example(cfg)), f"--set {item}")
    where = where or ("--set" if overrides else str(path) if path is not None else "defaults")
    check(cfg, where)
    if cross_check is not None:
        cross_check(cfg, where)
    return cfg


# --------------------------------------------------------------------------- output


def _plain(v):
    return [_plain(x) for x in v] if isinstance(v, (list, tuple)) else v


def to_dict(cfg: Any, drop_none: bool = True) -> dict[str, dict[str, Any]]:
    """Nested plain dict (tuples as lists); unset (None) values dropped unless ``drop_none=False``."""
    out: dict[str, dict[str, Any]] = {}
    for sec in sections(type(cfg)):
        s = getattr(cfg, sec)
        values = ((f.name, getattr(s, f.name)) for f in dataclasses.fields(s))
        out[sec] = {k: _plain(v) for k, v in values if v is not None or not drop_none}
    return out


def _scalar_toml(v: Any) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_scalar_toml(x) for x in v) + "]"
    import tomli_w

    return tomli_w.dumps({"v": v})[4:].rstrip("\n")


def to_toml(cfg: Any) -> str:
    """TOML text of a config, one line per key (unset values omitted); :func:`read_toml` and
    :func:`apply` read it back to the same config."""
    return "\n".join(f"[{sec}]\n" + "".join(f"{k} = {_scalar_toml(v)}\n" for k, v in values.items())
                     for sec, values in to_dict(cfg).items())


def meaning(md) -> str:
    """A field's doc with its bounds and choices."""
    doc = md.get("doc", "")
    if "range" in md:
        doc += f" [{_interval(md)[0]}]"
    if "choices" in md:
        doc += f" [one of: {_choices(md['choices'])}]"
    return doc


def reference(columns: dict[str, Any]) -> list[tuple[str, ...]]:
    """(key, type, one value per column, meaning) for every field; ``columns`` maps a column
    title to a config (all of one class), e.g. ``{"default": Config()}``."""
    cfgs = list(columns.values())
    rows = []
    for sec, cls in sections(type(cfgs[0])).items():
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            values = (getattr(getattr(c, sec), f.name) for c in cfgs)
            shown = ("unset" if v is None else repr(_plain(v)) for v in values)
            rows.append((f"{sec}.{f.name}", type_name(hints[f.name]), *shown, meaning(f.metadata)))
    return rows


def markdown(columns: dict[str, Any]) -> str:
    """The markdown table of :func:`reference` (``|`` in a cell escaped)."""
    escape = str.maketrans({"|": "\\|"})
    head = ["key", "type", *columns, "meaning"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key, tp, *values, doc in reference(columns):
        shown = " | ".join(f"`{v.translate(escape)}`" for v in values)
        lines.append(f"| `{key}` | {tp.translate(escape)} | {shown} | {doc.translate(escape)} |")
    return "\n".join(lines) + "\n"
