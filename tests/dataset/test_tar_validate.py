"""`synth validate` on hostile tar shards: every case is reported as a defect (never an
exception, never a read past what the manifest allows), and the tar-level checks are passed
on purpose (the manifest is rewritten to match the hostile tar and re-signed, as
--repair-index does) so that the member checks themselves are exercised."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from synth.dataset.index import repair_index
from synth.dataset.layout import frame_key
from synth.dataset.shards import open_dataset
from synth.dataset.tarshard import BLOCK, MAX_MEMBER_BYTES, TarRefused, iter_members, tar_manifest_path, tar_path
from synth.dataset.validate import validate_dataset
from synth.io import sha256_bytes
from tests.support import fake_frames as ff

pytest.importorskip("OpenEXR")

HASH = "f" * 64
PLAN = ff.plan(n_shards=1, n_expr=1, n_views=2)
SID = "shard_000000"
J0, E0 = f"{frame_key(0, 0, 0)}.json", f"{frame_key(0, 0, 0)}.exr"


@pytest.fixture
def shard(tmp_path):
    root = tmp_path / "d"
    ds = open_dataset(root, HASH, PLAN, shard_format="tar")
    ff.render_dataset(ds)
    with tarfile.open(tar_path(root, SID)) as tf:
        members = [(t.name, tf.extractfile(t).read()) for t in tf.getmembers()]
    assert validate_dataset(root).ok
    return root, members


def reg(name: str, data: bytes) -> tuple[tarfile.TarInfo, bytes]:
    ti = tarfile.TarInfo(name)
    ti.size = len(data)
    return ti, data


def special(name: str, kind, linkname: str = "") -> tuple[tarfile.TarInfo, None]:
    ti = tarfile.TarInfo(name)
    ti.type, ti.linkname = kind, linkname
    return ti, None


def build(entries, fmt=tarfile.USTAR_FORMAT) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=fmt) as tf:
        for ti, data in entries:
            tf.addfile(ti, io.BytesIO(data) if data is not None else None)
    return buf.getvalue()


def install(root: Path, data: bytes, edit=None) -> list[str]:
    """Put ``data`` in place of the shard's tar, make the manifest's container (and index) agree
    with it, and return validate's defect lines."""
    tp, mp = tar_path(root, SID), tar_manifest_path(root, SID)
    os.chmod(tp, 0o644)
    os.chmod(mp, 0o644)
    tp.write_bytes(data)
    m = json.loads(mp.read_bytes())
    m["container"].update(sha256=sha256_bytes(data), bytes=len(data))
    if edit:
        edit(m)
    mp.write_bytes(json.dumps(m).encode())
    repair_index(root, HASH)
    rep = validate_dataset(root)
    return [d.line() for d in rep.defects]


def kinds(lines: list[str]) -> set[str]:
    return {ln.split(": ")[1] for ln in lines}


CASES = {
    # name: (entries built from the good members, expected kind, expected text)
    "dotdot": (lambda m: [reg("../" + J0, m[J0])] + [reg(n, d) for n, d in m.items() if n != J0], "tar",
               "is not a frame file"),
    "absolute": (lambda m: [reg("/tmp/" + J0, m[J0])], "tar", "is not a frame file"),
    "subdir": (lambda m: [reg(f"{SID}/{J0}", m[J0])], "tar", "is not a frame file"),
    "symlink": (lambda m: [special(E0, tarfile.SYMTYPE, "/etc/passwd")], "tar", "symbolic link"),
    "hardlink": (lambda m: [special(E0, tarfile.LNKTYPE, "/etc/passwd")], "tar", "hard link"),
    "directory": (lambda m: [special(frame_key(0, 0, 0), tarfile.DIRTYPE)], "tar", "a directory"),
    "fifo": (lambda m: [special(E0, tarfile.FIFOTYPE)], "tar", "not a regular file"),
    "unexpected-name": (lambda m: [reg("evil.sh", b"rm -rf /")], "tar", "is not a frame file"),
    "duplicate": (lambda m: [reg(n, d) for n, d in m.items()] + [reg(J0, m[J0])], "tar", "more than once"),
    "extra-frame": (lambda m: [reg(n, d) for n, d in m.items()] + [reg(f"{frame_key(0, 0, 9)}.json", m[J0])],
                    "extra-file", "not in the manifest"),
    "out-of-order": (lambda m: [reg(n, d) for n, d in reversed(m.items())], "tar", "not in name order"),
    "missing-member": (lambda m: [reg(n, d) for n, d in m.items() if n != E0], "missing-file", "listed but not in"),
    "size-lie": (lambda m: [reg(n, d + b"x" if n == J0 else d) for n, d in m.items()], "checksum",
                 "manifest says"),
    "changed-bytes": (lambda m: [reg(n, d.replace(b'"frame_id"', b'"frame_iD"') if n == J0 else d)
                                 for n, d in m.items()], "checksum", "sha256 differs"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_members_are_defects(shard, case):
    root, members = shard
    make, kind, text = CASES[case]
    lines = install(root, build(make(dict(members))))
    assert lines, case
    assert any(f": {kind}: " in ln and text in ln for ln in lines), lines


def test_pax_and_gnu_extension_headers_are_refused(shard):
    root, members = shard
    ti, data = reg(J0, dict(members)[J0])
    ti.pax_headers = {"comment": "x" * 10}
    lines = install(root, build([(ti, data)], tarfile.PAX_FORMAT))
    assert any("pax header" in ln for ln in lines), lines
    lines = install(root, build([reg("a" * 150 + ".json", b"{}")], tarfile.GNU_FORMAT))
    assert any("GNU long-name header" in ln for ln in lines), lines


def test_a_huge_declared_size_is_refused_before_reading(shard):
    root, members = shard
    ti = tarfile.TarInfo(J0)
    ti.size = MAX_MEMBER_BYTES + 1
    data = ti.tobuf(tarfile.USTAR_FORMAT) + bytes(2 * BLOCK)  # a header and no data
    lines = install(root, data)
    assert any(f"limit {MAX_MEMBER_BYTES}" in ln for ln in lines), lines

    class Recorder(io.BytesIO):
        asked = 0

        def read(self, n=-1):
            Recorder.asked = max(Recorder.asked, n)
            return super().read(n)

    with pytest.raises(TarRefused, match="limit"):
        list(iter_members(Recorder(data), "t"))
    assert Recorder.asked == BLOCK  # only the header was read


def test_truncated_and_corrupt_headers(shard):
    root, members = shard
    good = build([reg(n, d) for n, d in members])
    lines = install(root, good[:BLOCK + 100])
    assert any("truncated" in ln for ln in lines), lines
    bad = bytearray(good)
    bad[10] ^= 0xFF  # inside the first header's name: its checksum no longer matches
    lines = install(root, bytes(bad))
    assert any("bad tar header" in ln for ln in lines), lines


def test_tar_level_checks(shard, tmp_path):
    root, members = shard
    tp, mp = tar_path(root, SID), tar_manifest_path(root, SID)
    data = tp.read_bytes()
    os.chmod(tp, 0o644)
    # a changed byte with the manifest untouched: the tar's sha256, then the member's
    bad = bytearray(data)
    off = json.loads(mp.read_bytes())["files"][J0]["offset"]
    bad[off + 2] ^= 0x01
    tp.write_bytes(bytes(bad))
    lines = [d.line() for d in validate_dataset(root).defects]
    assert any("shard_000000.tar sha256 differs" in ln for ln in lines) and \
        any(f"{J0} sha256 differs" in ln for ln in lines), lines
    assert not any("sha256 differs" in d.line() for d in validate_dataset(root, quick=True).defects)
    # the tar replaced by a symbolic link to a good copy
    (tmp_path / "copy.tar").write_bytes(data)
    tp.unlink()
    tp.symlink_to(tmp_path / "copy.tar")
    assert any("not a regular file" in d.line() for d in validate_dataset(root).defects)
    tp.unlink()
    assert any(": missing-file: shard_000000.tar is missing" in d.line() for d in validate_dataset(root).defects)
    # a manifest without its container entry
    tp.write_bytes(data)
    lines = install(root, data, edit=lambda m: m.pop("container"))
    assert any("'container'" in ln for ln in lines), lines


def test_cli_reports_a_hostile_tar_in_one_line_per_defect(shard):
    root, members = shard
    install(root, build([reg("../../escape.json", b"{}")]))
    p = subprocess.run([sys.executable, "-m", "synth.cli.main", "validate", str(root)], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2])))
    assert p.returncode == 1, p.stderr
    assert "shard_000000: tar: tar member '../../escape.json'" in p.stdout + p.stderr
    assert not (root.parent / "escape.json").exists()
