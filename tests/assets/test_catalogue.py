"""``synth assets list/validate`` and the external-pack checks, in pure Python (no bpy)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import pytest

from synth.assets.catalogue import default_manifest_dir, load_catalogue
from synth.assets.classes import CLASSES, NAMES
from synth.assets.validate import validate_manifest
from synth.cli.main import main
from synth.errors import SynthError
from synth.plan import assets

RIGS = Path(__file__).resolve().parents[2] / "blender_scripts" / "assets"
PACK = ('\n[[assets]]\nid = "{id}"\nclass = "headwear"\ngenerator = "blend:{path}"\nobject = "Cap"\n'
        'sha256 = "{sha}"\nlicence = "CC0-1.0"\ntags = ["headwear"]\n')


@pytest.fixture
def fake_rigs(tmp_path):
    """A rigs folder holding every module file, so tests do not depend on which rigs exist yet."""
    d = tmp_path / "rigs"
    d.mkdir()
    for c in CLASSES.values():
        (d / f"{c.rig}.py").write_text("")
    return d


@pytest.fixture
def manifest(tmp_path):
    """A copy of the embedded manifest with a packs/ asset root for headwear."""
    d = tmp_path / "manifest"
    shutil.copytree(default_manifest_dir(), d)
    (d / "packs").mkdir()
    text = (d / "headwear.toml").read_text()
    (d / "headwear.toml").write_text('asset_root = "packs"\n' + text)
    return d


def _add_pack(d: Path, rel: str, data: bytes | None = b"BLENDER-v405 fake pack", sha: str | None = None,
              id_: str = "pack_cap") -> str:
    if data is not None:
        f = d / "packs" / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(data)
    sha = sha or hashlib.sha256(data or b"").hexdigest()
    with (d / "headwear.toml").open("a") as f:
        f.write(PACK.format(id=id_, path=rel, sha=sha))
    return sha


def _defects(d: Path, rigs: Path) -> list[str]:
    return [x.line() for x in validate_manifest(d, rigs).defects]


def _asset(id_: str, cls: str, generator: str, parameters: str = "") -> str:
    """One [[assets]] block of a class file (procedural generator, MIT), with parameter lines."""
    text = f'\n[[assets]]\nid = "{id_}"\nclass = "{cls}"\ngenerator = "procedural:{generator}"\nlicence = "MIT"\n'
    return text + (f"[assets.parameters]\n{parameters}\n" if parameters else "")


def _expect(lines: list[str], want: list[tuple[str, str, str]]) -> None:
    """Exactly the defects ``want`` (what, where, fix: substrings of one line each)."""
    for what, where, fix in want:
        assert any(what in x and where in x and fix in x for x in lines), (what, lines)
    assert len(lines) == len(want), lines


def _cli(capsys, *args) -> tuple[int, str, str]:
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


# --------------------------------------------------------------------------- embedded manifest

def test_embedded_manifest_validates(fake_rigs):
    rep = validate_manifest(None, fake_rigs)
    assert rep.ok, [d.line() for d in rep.defects]
    assert rep.files == len(NAMES) + 1 and rep.assets >= 50 and rep.packs == 0


def test_cli_validate_embedded_manifest(capsys):
    rc, out, err = _cli(capsys, "assets", "validate")
    missing = sorted(c.rig for c in CLASSES.values() if not (RIGS / f"{c.rig}.py").is_file())
    lines = [x for x in out.splitlines() if x.strip()]
    if not missing:
        assert rc == 0 and lines[-1].endswith("OK") and len(lines) == 1, out
    else:  # other rigs still being written: the only defects are the missing rig files
        assert rc == 1 and len(lines) == len(missing), out
        assert all(x.startswith("no rig module for generator") for x in lines), out
        assert "defect" in err


def test_cli_list_table_and_json(capsys):
    rc, out, _ = _cli(capsys, "assets", "list", "--class", "glasses")
    assert rc == 0 and "rectangular" in out and "procedural:glasses_frame" in out and "MIT" in out
    assert "lens_width_m [0.045, 0.056] m" in out and "hair_strands" not in out
    rc, out, _ = _cli(capsys, "assets", "list", "--json")
    doc = json.loads(out)
    cat = load_catalogue()
    assert rc == 0 and doc["catalogue_sha256"] == cat.digest
    assert {a["class"] for a in doc["assets"]} == set(NAMES)
    assert len(doc["assets"]) == sum(len(c["assets"]) for c in cat.classes.values())
    rc, _, err = _cli(capsys, "assets", "list", "--class", "wig")
    assert rc == 2 and "unknown asset class 'wig'" in err and "\n" not in err.strip()


# --------------------------------------------------------------------------- broken manifests

def test_duplicate_id_bad_range_unknown_generator(manifest, fake_rigs, capsys):
    g = manifest / "glasses.toml"
    g.write_text(g.read_text() + _asset("round", "glasses", "glasses_frame"))
    h = manifest / "hair.toml"
    h.write_text(h.read_text().replace("length_m = { range = [0.003, 0.012]", "length_m = { range = [0.012, 0.003]")
                 + _asset("mystery", "hair", "hair_magic") + _asset("wrong_rig", "hair", "glasses_frame")
                 + _asset("bad_weights", "hair", "hair_strands", 'colour = { choices = ["a", "b"], weights = [1] }'))
    lines = _defects(manifest, fake_rigs)
    want = [("duplicate asset id 'round'", "glasses.toml asset round", "unique id"),
            ("range low > high", "hair.toml asset buzz_cut parameter length_m", "[low, high]"),
            ("unknown generator 'procedural:hair_magic'", "hair.toml asset mystery", "procedural:hair_strands"),
            ("builds class 'glasses', not 'hair'", "asset wrong_rig", "hair generator"),
            ("weights and choices differ in length", "asset bad_weights parameter colour", "one weight per choice")]
    _expect(lines, want)
    rc, out, _ = _cli(capsys, "assets", "validate", "--manifest-dir", str(manifest))
    assert rc == 1 and all(any(w[0] in x for x in out.splitlines()) for w in want)
    with pytest.raises(SynthError):  # the plan-time loader refuses the same folder
        load_catalogue(manifest)


def test_glasses_values_the_rig_would_refuse(manifest, fake_rigs):
    """An unknown glasses style (the asset id), colour or lens coating, or a lens reflectance
    outside [0, 0.25), is reported when the catalogue loads, not first by a render worker."""
    (manifest / "glasses.toml").write_text(
        'class = "glasses"\npresence = 0.25\n' + _asset("monocle", "glasses", "glasses_frame")
        + _asset("round", "glasses", "glasses_frame", 'lens_coating = { choices = ["anti_reflective", "mirror"] }\n'
                 'frame_colour = { value = "pink" }\nlens_reflectance = { range = [0.01, 0.3] }'))
    lines = _defects(manifest, fake_rigs)
    want = [("unknown glasses style 'monocle'", "asset monocle", "rectangular, round"),
            ("unknown lens_coating 'mirror'", "asset round parameter lens_coating", "anti_reflective, none"),
            ("unknown frame_colour 'pink'", "asset round parameter frame_colour", "black"),
            ("lens_reflectance outside [0, 0.25)", "asset round parameter lens_reflectance", "0.04 = uncoated")]
    _expect(lines, want)
    with pytest.raises(SynthError, match="unknown glasses style 'monocle'"):  # the plan-time loader
        load_catalogue(manifest)


def test_a_parameter_no_rig_reads_is_a_defect(manifest, fake_rigs):
    """Each class's parameters are its record's fields (synth/assets/params.py): a name the rig
    does not read is reported, and refused when the catalogue loads (plan time)."""
    with (manifest / "skin.toml").open("a") as f:
        f.write(_asset("glowing_skin", "skin", "skin_shader", "glow = { range = [0.0, 1.0] }"))
    _expect(_defects(manifest, fake_rigs), [("parameter 'glow' is not one the skin rig reads",
                                              "asset glowing_skin parameter glow", "synth/assets/params.py")])
    with pytest.raises(SynthError, match="parameter 'glow'"):
        load_catalogue(manifest)


def test_missing_class_unknown_file_rule_tags_and_schema(manifest, fake_rigs):
    (manifest / "iris.toml").unlink()
    (manifest / "wigs.toml").write_text('class = "hair"\n')
    r = manifest / "rules.toml"
    r.write_text(r.read_text() + '\n[[exclude]]\nif_tag = "tiara"\nexcludes_tags = ["long_hair"]\n')
    m = manifest / "makeup.toml"
    m.write_text(m.read_text() + '\n[[assets]]\nid = "Bad Id"\nclass = "makeup"\ngenerator = "procedural:makeup_layer"\n')
    lines = _defects(manifest, fake_rigs)
    assert any("class 'iris' has no manifest file" in x for x in lines)
    assert any("unknown asset class file 'wigs.toml'" in x for x in lines)
    assert any("rule names tag 'tiara'" in x and "rules.toml exclude #2" in x for x in lines)
    assert any("schema:" in x and "'licence' is a required property" in x and "makeup.toml" in x for x in lines)
    assert any("schema:" in x and "Bad Id" in x for x in lines)


def test_missing_rig_module_is_reported_once_per_generator(tmp_path, fake_rigs):
    (fake_rigs / "hair.py").unlink()
    lines = _defects(None, fake_rigs)
    assert len(lines) == 1, lines
    assert lines[0].startswith("no rig module for generator 'procedural:hair_strands'") and "hair.py is missing" in lines[0]
    assert "hair.toml" in lines[0] and lines[0].endswith("add blender_scripts/assets/hair.py with build(ctx, entry)")


# --------------------------------------------------------------------------- external packs

def test_good_pack_validates_loads_and_is_sampled(manifest, fake_rigs, capsys):
    sha = _add_pack(manifest, "caps/cap.blend")
    assert _defects(manifest, fake_rigs) == []
    cat = load_catalogue(manifest)
    rec = cat.packs["headwear/pack_cap"]
    assert rec["file"] == "caps/cap.blend" and rec["sha256"] == sha and rec["object"] == "Cap"
    assert Path(rec["asset_root"]) == (manifest / "packs").resolve() and rec["anchor"] == "head"
    picks = assets.sample_assets_batch(3, range(4000), cat)
    got = [p["headwear"] for p in picks if p["headwear"] and p["headwear"]["id"] == "pack_cap"]
    assert got and all(p["pack"] == rec for p in got)
    assert all("pack" not in p[c] for p in picks for c in NAMES if p[c] and p[c]["id"] != "pack_cap")
    rc, out, _ = _cli(capsys, "assets", "list", "--class", "headwear", "--manifest-dir", str(manifest))
    assert rc == 0 and "blend:caps/cap.blend" in out and sha[:12] in out
    # '#NAME' form of the object is accepted as well
    _add_pack(manifest, "caps/cap2.blend", data=b"another", id_="pack_cap2")
    t = manifest / "headwear.toml"
    t.write_text(t.read_text().replace('generator = "blend:caps/cap2.blend"\nobject = "Cap"\n',
                                       'generator = "blend:caps/cap2.blend#Beanie"\n'))
    assert _defects(manifest, fake_rigs) == []
    assert load_catalogue(manifest).packs["headwear/pack_cap2"]["object"] == "Beanie"


def test_asset_root_and_folder_do_not_change_the_digest(manifest):
    assert load_catalogue(manifest).digest == load_catalogue().digest


def test_checksum_mismatch(manifest, fake_rigs):
    _add_pack(manifest, "cap.blend", sha="0" * 64)
    lines = _defects(manifest, fake_rigs)
    assert len(lines) == 1 and "does not match its checksum" in lines[0] and "cap.blend" in lines[0]
    assert "asset pack_cap" in lines[0] and "update sha256" in lines[0]
    with pytest.raises(SynthError) as e:
        load_catalogue(manifest)
    assert "cap.blend" in str(e.value) and "checksum" in str(e.value) and "\n" not in str(e.value)


def test_path_escape_via_dotdot(manifest, fake_rigs):
    outside = manifest.parent / "outside.blend"
    outside.write_bytes(b"evil")
    _add_pack(manifest, "../../outside.blend", data=None, sha=hashlib.sha256(b"evil").hexdigest())
    lines = _defects(manifest, fake_rigs)
    assert len(lines) == 1 and "escapes the asset root" in lines[0] and "via '..'" in lines[0], lines
    with pytest.raises(SynthError, match="escapes the asset root"):
        load_catalogue(manifest)


def test_path_escape_via_absolute_path(manifest, fake_rigs):
    outside = manifest.parent / "outside.blend"
    outside.write_bytes(b"evil")
    _add_pack(manifest, str(outside), data=None, sha=hashlib.sha256(b"evil").hexdigest())
    lines = _defects(manifest, fake_rigs)
    assert len(lines) == 1 and "escapes the asset root" in lines[0] and "absolute path" in lines[0], lines


def test_path_escape_via_symlink(manifest, fake_rigs):
    outside = manifest.parent / "outside.blend"
    outside.write_bytes(b"evil")
    os.symlink(outside, manifest / "packs" / "link.blend")
    (manifest / "packs" / "sub").symlink_to(manifest.parent, target_is_directory=True)
    sha = hashlib.sha256(b"evil").hexdigest()
    _add_pack(manifest, "link.blend", data=None, sha=sha, id_="via_file_link")
    _add_pack(manifest, "sub/outside.blend", data=None, sha=sha, id_="via_dir_link")
    lines = _defects(manifest, fake_rigs)
    assert len(lines) == 2 and all("escapes the asset root" in x and "via a symlink" in x for x in lines), lines
    # a symlink that stays inside the root is fine
    (manifest / "packs" / "real.blend").write_bytes(b"fine")
    os.symlink(manifest / "packs" / "real.blend", manifest / "packs" / "inside.blend")
    h = manifest / "headwear.toml"
    h.write_text(h.read_text().split("\n[[assets]]\nid = \"via_file_link\"")[0])
    _add_pack(manifest, "inside.blend", data=None, sha=hashlib.sha256(b"fine").hexdigest(), id_="inside")
    assert _defects(manifest, fake_rigs) == []


def test_missing_file_licence_object_and_class(manifest, fake_rigs):
    _add_pack(manifest, "gone.blend", data=None, sha="1" * 64)
    lines = _defects(manifest, fake_rigs)
    assert len(lines) == 1 and "external pack file 'gone.blend' not found" in lines[0], lines
    with pytest.raises(SynthError, match="gone.blend"):
        load_catalogue(manifest)
    # a pack with an empty licence, no object name, no sha256, for a shader class
    h = manifest / "headwear.toml"
    h.write_text(h.read_text().replace('object = "Cap"\n', "").replace('licence = "CC0-1.0"', 'licence = ""'))
    (manifest / "packs" / "gone.blend").write_bytes(b"x")
    s = manifest / "skin.toml"
    s.write_text(s.read_text() + '\n[[assets]]\nid = "pack_skin"\nclass = "skin"\ngenerator = "blend:gone.blend"\n'
                 'licence = "CC0-1.0"\nobject = "S"\n')
    lines = "\n".join(_defects(manifest, fake_rigs))
    assert "names no object or collection" in lines
    assert "licence" in lines
    assert "'sha256' is a required property" in lines and "skin.toml" in lines
    assert "class 'skin' cannot come from an external pack" in lines
