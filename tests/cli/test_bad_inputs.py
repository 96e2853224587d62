"""Bad inputs through the real command line (a subprocess per case), for every subcommand.

Each case prepares its inputs in a fresh directory, runs ``python -m synth.cli.main ...`` there
and checks the promise of docs/reliability.md: the documented exit code, exactly one
``synth: error:`` line on stderr saying what went wrong, no traceback, and the directory left
exactly as it was (no new, changed or removed file or directory: a refused command writes
nothing). No Blender is needed: every case is refused before a worker would start.
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.support import datasets
from tests.support.farm_helpers import SYNTH, env
from tests.support.toy_model import write_toy_model

pytest.importorskip("OpenEXR")

DEEP = "[" * 100_000 + "]" * 100_000


@dataclass(frozen=True)
class Fixtures:
    model: Path  # the toy head model (.npz)
    clean: Path  # a complete dataset (2 shards) whose plan the toy model gives


@dataclass(frozen=True)
class Case:
    id: str
    make: Callable[[Path, Fixtures], list]  # prepares files in the case directory; returns the arguments
    rc: int
    says: str  # part of the error line


# -- inputs --------------------------------------------------------------------------------------

def write(d: Path, name: str, data: str | bytes) -> Path:
    p = d / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(data if isinstance(data, bytes) else data.encode())
    return p


def copy_clean(d: Path, fx: Fixtures) -> Path:
    return datasets.writable_copy(fx.clean, d / "ds")


def ds_with(edit: Callable[[Path], None]) -> Callable[[Path, Fixtures], Path]:
    def make(d: Path, fx: Fixtures) -> Path:
        root = copy_clean(d, fx)
        edit(root)
        return root
    return make


def set_json(name: str, value) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        (root / name).write_text(value if isinstance(value, str) else json.dumps(value))
    return edit


def bad_index_entry(root: Path) -> None:
    idx = json.loads((root / "index.json").read_text())
    idx["shards"]["shard_000000"] = 5
    (root / "index.json").write_text(json.dumps(idx))


def lost_signatures(root: Path) -> None:
    """index.json and the commit records deleted: nothing says what was committed."""
    (root / "index.json").unlink()
    __import__("shutil").rmtree(root / ".commits")


def bad_expected(root: Path) -> None:
    info = json.loads((root / "dataset.json").read_text())
    info["expected"]["shard_000000"] = 5
    (root / "dataset.json").write_text(json.dumps(info))


def frame_symlink(target: str | None) -> Callable[[Path], None]:
    def edit(root: Path) -> None:
        sd, js = datasets.first_frame(root)
        exr = js.with_suffix(".exr")
        if target is None:  # a copy outside the dataset, same bytes
            outside = root.parent / "outside.exr"
            outside.write_bytes(exr.read_bytes())
            dest = str(outside)
        else:
            dest = target
        exr.unlink()
        exr.symlink_to(dest)
    return edit


def stray_tar(root: Path) -> None:
    import io
    import tarfile

    with tarfile.open(root / "shards" / "evil.tar", "w") as tf:
        data = b"x"
        for name in ("../escape.txt", "/abs.txt"):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))


def nested_frame(root: Path) -> None:
    sd, js = datasets.first_frame(root)
    js.write_text(DEEP)
    datasets.reseal(sd, js.name)


def render_args(d: Path, fx: Fixtures, out: Path | None = None, *extra) -> list:
    return [*datasets.render_args(1, fx.model, out or d / "out"), *extra]


def edited_plan(d: Path, fx: Fixtures) -> list:
    from renderer_jobs.submit import prepare_plan

    pdir = prepare_plan(d / "p", 1, None, datasets.SETS, datasets.SEED, fx.model)
    spec = pdir / "shards" / "shard_000000.json"
    s = json.loads(spec.read_text())
    s["run_seed"] = 99
    spec.write_text(json.dumps(s))
    return ["render", "--plan", pdir, "--out", d / "out"]


def fake_npz(meta: bytes) -> Callable[[Path, Fixtures], Path]:
    def make(d: Path, fx: Fixtures) -> Path:
        import numpy as np

        p = d / "m.npz"
        np.savez(p, meta=np.frombuffer(meta, np.uint8))
        return p
    return make


def complete_ds(edit: Callable[[Path], None]) -> Callable[[Path, Fixtures], list]:
    """A rerun of the render that made the clean dataset, after ``edit`` damaged it."""
    def make(d: Path, fx: Fixtures) -> list:
        root = copy_clean(d, fx)
        edit(root)
        return datasets.render_args(2, fx.model, root)
    return make


def a(*args) -> Callable[[Path, Fixtures], list]:
    """Arguments after ``make``s of their own: a callable argument is called with (d, fx)."""
    return lambda d, fx: [x(d, fx) if callable(x) else x for x in args]


def p(name: str) -> Callable[[Path, Fixtures], Path]:
    return lambda d, fx: d / name


def f(name: str, data: str | bytes) -> Callable[[Path, Fixtures], Path]:
    return lambda d, fx: write(d, name, data)


def m(d: Path, fx: Fixtures) -> Path:
    return fx.model


def lidless(d: Path, fx: Fixtures) -> Path:
    """The toy model without its upper-lid lines: no eyelashes can be rooted on it."""
    from synth.model.format import read_model, write_model

    data = read_model(fx.model)
    del data.regions["eyelid_l_upper"]
    return write_model(data, d / "lidless.npz")


def user_dir(d: Path, fx: Fixtures) -> Path:
    write(d, "out/notes.txt", "mine")
    return d / "out"


LATIN = b"[dataset]\nseed = 1 # caf\xe9\n"
HDRI = '[lighting]\nenvironment = "hdri"\nhdri_files = ["/nonexistent/sky.exr"]\n'
DEEP_TOML = "x = " + "[" * 50_000 + "]" * 50_000 + "\n"

CASES = [
    # synth render
    Case("render-seed-negative", lambda d, fx: render_args(d, fx, None, "--seed", "-5"), 2, "--seed"),
    Case("render-seed-2**64", lambda d, fx: render_args(d, fx, None, "--seed", str(2**64)), 2, "--seed"),
    Case("render-identities-float", a("render", "--identities", "1e12", "--out", p("out")), 2, "--identities"),
    Case("render-identities-huge", a("render", "--identities", "1000000000000", "--model", m, "--out", p("out")), 2,
         "identity indices"),
    Case("render-identities-zero", a("render", "--identities", "0", "--out", p("out")), 2, "--identities"),
    Case("render-views-1000", a("render", "-n", "1", "--views", "1000", "--model", m, "--out", p("out")), 2,
         "at most 100"),
    Case("render-expressions-0", a("render", "-n", "1", "--expressions", "0", "--out", p("out")), 2,
         "--expressions"),
    Case("render-out-is-a-file", lambda d, fx: render_args(d, fx, write(d, "out", "x")), 2, "not a directory"),
    Case("render-out-holds-user-files", lambda d, fx: render_args(d, fx, user_dir(d, fx)), 2,
         "not empty and holds no dataset.json"),
    Case("render-config-not-utf8", a("render", "-n", "1", "--config", f("c.toml", LATIN), "--out", p("out")), 2,
         "not UTF-8"),
    Case("render-config-missing", a("render", "-n", "1", "--config", p("nope.toml"), "--out", p("out")), 2, "nope"),
    Case("render-config-nested", a("render", "-n", "1", "--config", f("c.toml", DEEP_TOML), "--out", p("out")), 2,
         "nested too deeply"),
    Case("render-hdri-missing", lambda d, fx: render_args(d, fx, None, "--config", write(d, "c.toml", HDRI)), 2,
         "HDR environment file not found"),
    Case("render-set-unknown-key", a("render", "-n", "1", "--set", "nosuch.key=1", "--out", p("out")), 2, "nosuch"),
    Case("render-plan-edited", edited_plan, 2, "changed after planning"),
    Case("render-plan-and-identities", a("render", "--plan", p("p"), "-n", "1", "--out", p("out")), 2,
         "planning options"),
    Case("render-plan-not-a-plan", a("render", "--plan", lambda d, fx: write(d, "p/x", "x").parent, "--out",
                                     p("out")), 2, "no plan.json"),
    Case("render-backend-unknown", a("render", "-n", "1", "--backend", "cloud", "--out", p("out")), 2, "backend"),
    Case("render-model-missing", a("render", "-n", "1", "--model", p("nope.npz"), "--out", p("out")), 2, "model"),
    Case("render-model-garbage", a("render", "-n", "1", "--model", f("m.npz", b"PK\x03\x04junk"), "--out",
                                   p("out")), 2, "npz"),
    Case("render-other-plan-in-out", lambda d, fx: [*datasets.render_args(2, fx.model, copy_clean(d, fx)),
                                                    "--seed", "8"], 2, "different plan"),
    Case("render-dataset-without-plan", lambda d, fx: [*datasets.render_args(
        2, fx.model, ds_with(lambda r: __import__("shutil").rmtree(r / "plan"))(d, fx)), "--seed", "8"], 2,
         "different plan"),
    Case("render-index-entry-not-object", complete_ds(bad_index_entry), 2, "index.json is damaged"),
    Case("render-index-nested", complete_ds(set_json("index.json", DEEP)), 2, "nested"),
    Case("render-signatures-lost", complete_ds(lost_signatures), 2, "has no commit record"),
    # synth plan
    Case("plan-seed-negative", a("plan", "-n", "1", "--seed", "-1", "--out", p("out")), 2, "--seed"),
    Case("plan-out-is-a-file", a("plan", "-n", "1", "--model", m, "--out", f("out", "x")), 2, "not a directory"),
    Case("plan-model-cannot-carry-class", a("plan", "-n", "1", "--model", lidless, "--out", p("out")), 2,
         "cannot carry asset class eyelashes: the model has no eyelid_l_upper region"),
    Case("render-model-cannot-carry-class", a("render", "-n", "1", "--model", lidless, "--out", p("out")), 2,
         "assets.disabled_classes=[\"eyelashes\"]"),
    Case("plan-identities-zero", a("plan", "-n", "0", "--model", m, "--out", p("out")), 2, "at least 1"),
    Case("plan-start-negative", a("plan", "-n", "1", "--start", "-1", "--model", m, "--out", p("out")), 2,
         "identity indices"),
    Case("plan-config-not-utf8", a("plan", "-n", "1", "--config", f("c.toml", LATIN), "--out", p("out")), 2,
         "not UTF-8"),
    Case("plan-nul-in-manifest-dir", a("plan", "-n", "1", "--config", f("c.toml", '[assets]\nmanifest_dir = '
                                                                       '"a\\u0000b"\n'), "--out", p("out")), 2,
         "a\\x00b"),
    Case("plan-unknown-option", a("plan", "--expressions", "3", "--out", p("out")), 2, "No such option"),
    # synth validate
    Case("validate-missing", a("validate", p("nope")), 2, "not found"),
    Case("validate-a-file", a("validate", f("afile", "x")), 2, "not a directory"),
    Case("validate-empty-dir", a("validate", lambda d, fx: (d / "e").mkdir() or d / "e"), 2, "no dataset.json"),
    Case("validate-dataset-json-garbage", a("validate", ds_with(set_json("dataset.json", "{"))), 2,
         "dataset.json cannot be read"),
    Case("validate-dataset-json-nested", a("validate", ds_with(set_json("dataset.json", DEEP))), 2, "nested"),
    Case("validate-dataset-json-bad-expected", a("validate", ds_with(bad_expected)), 2, "dataset.json is damaged"),
    Case("validate-index-entry-not-object", a("validate", ds_with(bad_index_entry)), 1, "defect"),
    Case("validate-index-nested", a("validate", ds_with(set_json("index.json", DEEP))), 1, "defect"),
    Case("validate-index-missing", a("validate", ds_with(lambda r: (r / "index.json").unlink())), 1, "defect"),
    Case("validate-signatures-lost", a("validate", ds_with(lost_signatures)), 1, "defect"),
    Case("validate-frame-symlink-outside", a("validate", ds_with(frame_symlink(None))), 1, "defect"),
    Case("validate-frame-symlink-dev-zero", a("validate", "--quick", ds_with(frame_symlink("/dev/zero"))), 1,
         "defect"),
    Case("validate-stray-tar", a("validate", ds_with(stray_tar)), 1, "defect"),
    Case("validate-nested-frame-json", a("validate", ds_with(nested_frame)), 1, "defect"),
    Case("validate-laundered-frame", a("validate", ds_with(datasets.tamper_frame)), 1, "defect"),
    Case("validate-jobs-zero", a("validate", "--jobs", "0", ds_with(lambda r: None)), 2, "--jobs"),
    # synth preview
    Case("preview-missing", a("preview", p("nope")), 2, "not found"),
    Case("preview-unknown-shard", a("preview", ds_with(lambda r: None), "--shard", "shard_000009", "-o",
                                    p("x.png")), 2, "shard_000009"),
    Case("preview-index-damaged", a("preview", ds_with(bad_index_entry), "-o", p("x.png")), 2, "index.json"),
    Case("preview-tile-too-small", a("preview", ds_with(lambda r: None), "--tile", "1"), 2, "--tile"),
    # synth config
    Case("config-show-missing", a("config", "show", "--config", p("nope.toml")), 2, "nope"),
    Case("config-show-bad-set", a("config", "show", "--set", "dataset.seed"), 2, "dataset.seed"),
    Case("config-show-not-utf8", a("config", "show", "--config", f("c.toml", LATIN)), 2, "UTF-8"),
    # synth model
    Case("model-info-missing", a("model", "info", "--model", p("nope.npz")), 2, "not found"),
    Case("model-info-garbage", a("model", "info", "--model", f("m.npz", b"garbage")), 2, "npz"),
    Case("model-info-meta-not-object", a("model", "info", "--model", fake_npz(b"[1, 2]")), 2, "synth"),
    Case("model-info-meta-nested", a("model", "info", "--model", fake_npz(DEEP.encode())), 2, "nested"),
    Case("model-sample-out-is-a-file", a("model", "sample", "--out", f("out", "x")), 2, "not empty"),
    Case("model-sample-format", a("model", "sample", "--format", "stl", "--out", p("out")), 2, "stl"),
    Case("model-import-ict-missing", a("model", "import", "ict-facekit", p("nope"), "-o", p("m.npz")), 2, "nope"),
    Case("model-import-flame-garbage", a("model", "import", "flame", f("f.pkl", b"garbage"), "-o", p("m.npz")), 2,
         ""),
    # synth assets
    Case("assets-validate-missing-dir", a("assets", "validate", "--manifest-dir", p("nope")), 2, "not found"),
    Case("assets-list-dir-is-a-file", a("assets", "list", "--manifest-dir", f("am", "x")), 2, ""),
    # synth export
    Case("export-nerfstudio-missing", a("export", "nerfstudio", p("nope"), "-o", p("ns")), 2, "not a dataset"),
    Case("export-nerfstudio-out-not-empty", a("export", "nerfstudio", ds_with(lambda r: None), "-o", user_dir), 2,
         "not empty"),
    Case("export-nerfstudio-no-such-identity", a("export", "nerfstudio", ds_with(lambda r: None), "-i", "99", "-o",
                                                 p("ns")), 2, "no committed frames of identity 99"),
    Case("export-usd-bad-extension", a("export", "usd", ds_with(lambda r: None), "-o", p("x.txt")), 2,
         "USD file name"),
    Case("export-usd-unknown-shard", a("export", "usd", ds_with(lambda r: None), "-s", "shard_000009", "-o",
                                       p("x.usda")), 2, "shard_000009"),
    # synth report
    Case("report-missing", a("report", p("nope")), 2, "not found"),
    Case("report-a-file", a("report", f("afile", "x")), 2, "not a directory"),
    Case("report-index-damaged", a("report", ds_with(bad_index_entry), "-o", p("r.html")), 2, "index.json"),
    Case("report-max-shards-zero", a("report", ds_with(lambda r: None), "--max-shards", "0"), 2, "--max-shards"),
    Case("report-out-dir-missing", a("report", ds_with(lambda r: None), "-o", p("nodir/r.html")), 2,
         "cannot write the report"),
    # synth prior
    Case("prior-info-missing", a("prior", "info", p("nope")), 2, ""),
    Case("prior-render-missing", a("prior", "render", p("nope"), "-i", "0", "-e", "0", "-o", p("o")), 2, ""),
    Case("prior-train-missing-dataset", a("prior", "train", p("nope"), "--out", p("run")), 2, "nope"),
]


def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root`` (links not followed) with its kind, size and modification time."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for n in dirnames + filenames:
            pth = Path(dirpath) / n
            st = os.lstat(pth)
            out[str(pth.relative_to(root))] = (st.st_mode, st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture(scope="module")
def fx(tmp_path_factory) -> Fixtures:
    base = tmp_path_factory.mktemp("bad_inputs")
    model = write_toy_model(base / "toy.npz")
    return Fixtures(model=model, clean=datasets.fake_render(base / "clean", model, n=2))


def test_the_table_covers_every_subcommand():
    assert len(CASES) >= 40 and len({c.id for c in CASES}) == len(CASES)
    heads = {c.id.split("-")[0] for c in CASES}
    assert heads >= {"render", "plan", "validate", "preview", "config", "model", "assets", "prior", "export", "report"}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_line_and_writes_nothing(case: Case, fx: Fixtures, tmp_path: Path):
    d = tmp_path / "case"
    d.mkdir()
    args = [str(x) for x in case.make(d, fx)]
    before = snapshot(d)
    proc = subprocess.run([*SYNTH, *args], cwd=d, env=env(), capture_output=True, text=True, timeout=300)
    out = proc.stdout + proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("synth: error:")]
    assert "Traceback" not in out, out
    assert len(errors) == 1, out
    assert case.says in errors[0], errors[0]
    assert proc.returncode == case.rc, out
    assert snapshot(d) == before, f"the command changed the file system:\n{out}"
