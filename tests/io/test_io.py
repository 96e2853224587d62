"""synth.io: atomic files and directories, strict JSON, sha256 (against hashlib), the cache folder."""

from __future__ import annotations

import hashlib
import math
import os

import numpy as np
import pytest

from synth import io as sio
from synth.io import files, hashing


def _leftovers(d):
    return [n for n in os.listdir(d) if sio.is_temp_name(n)]


# --------------------------------------------------------------------------- files


def test_temp_name_is_a_hidden_sibling_and_unique(tmp_path):
    final = tmp_path / "a.json"
    names = {sio.temp_name(final) for _ in range(50)}
    assert len(names) == 50
    for t in names:
        assert t.parent == tmp_path and sio.is_temp_name(t.name) and "a.json" in t.name
    assert not sio.is_temp_name("a.json") and not sio.is_temp_name(".a.json") and not sio.is_temp_name("a.tmp")


@pytest.mark.parametrize("data", [b"", b"x", bytes(range(256)) * 1000])
def test_atomic_write_bytes_writes_and_replaces(tmp_path, data):
    p = tmp_path / "f.bin"
    p.write_bytes(b"old")
    sio.atomic_write_bytes(p, data)
    assert p.read_bytes() == data
    sio.atomic_write_bytes(p, data + b"!", durable=False)
    assert p.read_bytes() == data + b"!"
    assert _leftovers(tmp_path) == []


def test_atomic_write_bytes_survives_short_writes(tmp_path, monkeypatch):
    real = os.write
    monkeypatch.setattr(files.os, "write", lambda fd, b: real(fd, bytes(b[:7])))
    data = np.random.default_rng(0).bytes(1000)
    sio.atomic_write_bytes(tmp_path / "f", data)
    assert (tmp_path / "f").read_bytes() == data


def test_atomic_write_bytes_failure_keeps_the_old_file(tmp_path, monkeypatch):
    p = tmp_path / "f"
    p.write_bytes(b"old")

    def boom(fd, b):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.os, "write", boom)
    with pytest.raises(OSError):
        sio.atomic_write_bytes(p, b"new")
    assert p.read_bytes() == b"old" and _leftovers(tmp_path) == []


def test_atomic_place_failure_in_fill_and_in_rename(tmp_path, monkeypatch):
    p = tmp_path / "f"

    def fill(tmp):
        tmp.write_bytes(b"half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sio.atomic_place(p, fill)
    assert not p.exists() and _leftovers(tmp_path) == []
    monkeypatch.setattr(files.os, "replace", lambda a, b: (_ for _ in ()).throw(OSError(18, "cross-device")))
    with pytest.raises(OSError):
        sio.atomic_place(p, lambda tmp: tmp.write_bytes(b"x"))
    assert not p.exists() and _leftovers(tmp_path) == []


def test_atomic_dir_creates_replaces_empty_and_cleans_up(tmp_path):
    out = tmp_path / "out"
    with sio.atomic_dir(out) as d:
        assert d.parent == tmp_path and sio.is_temp_name(d.name) and not out.exists()
        (d / "a").write_text("1")
    assert (out / "a").read_text() == "1"
    empty = tmp_path / "empty"
    empty.mkdir()
    with sio.atomic_dir(empty, durable=False) as d:
        (d / "b").write_text("2")
    assert os.listdir(empty) == ["b"]
    assert _leftovers(tmp_path) == []


def test_atomic_dir_error_leaves_nothing_and_never_replaces_content(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with sio.atomic_dir(out) as d:
            (d / "a").write_text("1")
            raise RuntimeError("stop")
    assert not out.exists() and _leftovers(tmp_path) == []
    out.mkdir()
    (out / "keep").write_text("k")
    with pytest.raises(OSError):
        with sio.atomic_dir(out) as d:
            (d / "a").write_text("1")
    assert os.listdir(out) == ["keep"] and _leftovers(tmp_path) == []


def test_atomic_dir_body_can_keep_the_existing_directory(tmp_path):
    import shutil

    out = tmp_path / "out"
    out.mkdir()
    with sio.atomic_dir(out) as d:
        (d / "a").write_text("1")
        shutil.rmtree(d)
    assert out.is_dir() and os.listdir(out) == [] and _leftovers(tmp_path) == []


# --------------------------------------------------------------------------- JSON


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, {"a": [1.0, math.nan]}])
def test_dumps_json_refuses_non_finite(bad):
    with pytest.raises(ValueError):
        sio.dumps_json(bad)


@pytest.mark.parametrize("text", ["NaN", "[Infinity]", '{"a": -Infinity}'])
def test_loads_json_refuses_non_standard_constants(text):
    with pytest.raises(ValueError):
        sio.loads_json(text)


def test_json_round_trip_utf8_newline(tmp_path):
    obj = {"name": "Zoë ☺", "x": [0.1, -0.0, 1e-300, 1.7976931348623157e308], "n": None, "t": True}
    data = sio.dumps_json(obj)
    assert data.endswith(b"\n") and "Zoë".encode() in data
    assert sio.loads_json(data) == obj and sio.loads_json(data.decode()) == obj
    p = tmp_path / "o.json"
    assert sio.atomic_write_json(p, obj, indent=None) == p.read_bytes() == sio.dumps_json(obj, indent=None)


# --------------------------------------------------------------------------- sha256


@pytest.mark.parametrize("size", [0, 1, hashing.BLOCK - 1, hashing.BLOCK, hashing.BLOCK + 1, 3 * hashing.BLOCK + 5])
def test_sha256_against_hashlib(tmp_path, size):
    data = np.random.default_rng(size).bytes(size)
    p = tmp_path / "f"
    p.write_bytes(data)
    want = hashlib.sha256(data).hexdigest()
    assert sio.sha256_bytes(data) == want
    assert sio.sha256_file(p) == want
    assert sio.file_digest(p, sync=True) == (want, size)


def test_sha256_file_missing(tmp_path):
    with pytest.raises(FileNotFoundError):
        sio.sha256_file(tmp_path / "nope")


# --------------------------------------------------------------------------- cache


def test_cache_dir_from_environment(tmp_path, monkeypatch):
    d = tmp_path / "a" / "b"
    monkeypatch.setenv("SYNTH_CACHE_DIR", str(d))
    assert sio.cache_dir() == d and d.is_dir()
    monkeypatch.delenv("SYNTH_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert sio.cache_dir().is_dir()


@pytest.mark.parametrize("text", [b'{"a": [1.5, -0.0, 1e-320, 2.2250738585072011e-308], "b": {"c": null}}',
                                  b"[18446744073709551615, -9223372036854775808]", b"123456789012345678901234567890",
                                  b'{"a": 1e400}', b'"\\ud800"', b'{"k": 1, "k": 2}', b"[" * 64 + b"]" * 64,
                                  b'{"a":18446744073709551616}', b"[1,\n\t-99999999999999999999 ]",
                                  b'{"s": "00000000000000000000000", "n": [0.12345678901234567890123]}',
                                  b'["x 12345678901234567890 y", 12345678901234567890123e-3]'])
def test_loads_json_gives_what_json_gives(text):
    import json

    assert repr(sio.loads_json(text)) == repr(json.loads(text))  # repr: int stays int, -0.0 stays -0.0


@pytest.mark.parametrize("depth", [64, 65])
@pytest.mark.parametrize("inner", [b'"]]]}}"', b'"[[[{{"', b'"a\\"]]"', b'{"k]": "[", "v": ["]"]}', b'""'])
def test_the_depth_limit_ignores_brackets_in_strings(depth, inner):
    """Brackets inside strings (with and without escapes) neither hide nor add nesting: 64 is
    accepted, 65 refused, whichever path measures the depth."""
    outer = depth - (2 if inner.startswith(b"{") else 0)
    text = b"[" * outer + inner + b"]" * outer
    if depth <= 64:  # synth.io.jsonio.MAX_DEPTH
        assert sio.loads_json(text) is not None
    else:
        with pytest.raises(sio.JSONError, match=f"nested {depth} levels deep"):
            sio.loads_json(text)


@pytest.mark.parametrize("text, says", [(b"[" * 65 + b"]" * 65, "nested 65 levels deep"),
                                        (b"[" * 2000 + b"]" * 2000, "nested 2000 levels deep"),
                                        (b"[1, 2", "Expecting ','"), (b'"\xff"', "not UTF-8")])
def test_loads_json_refuses_with_the_same_reasons(text, says):
    with pytest.raises(sio.JSONError, match=says):
        sio.loads_json(text)
