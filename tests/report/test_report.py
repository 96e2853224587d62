"""``synth report``: the JSON summary against the frames it reads, a dataset in progress, the
render logs, and the HTML page (one file, every figure embedded)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from renderer_jobs.events import BatchEnd, Error, Frame, Start, encode
from synth.appearance.skin import individual_typology_angle, skin_albedo
from synth.report import plots
from synth.report.html import write_report
from tests.support.datasets import model_dataset


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    ds, _ = model_dataset(tmp_path_factory.mktemp("rep") / "ds", identities=3, expressions=3, views=4)
    return ds


def _frames(ds: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(ds.glob("shards/*/*.json")) if p.name != "manifest.json"}


def _brute_smallest_angle(cams) -> float:
    best = 180.0
    for a in range(len(cams)):
        for b in range(a + 1, len(cams)):
            u, v = (np.asarray(c["target"]) - np.asarray(c["camera_to_world"])[:3, 3] for c in (cams[a], cams[b]))
            cos = u @ v / np.linalg.norm(u) / np.linalg.norm(v)
            best = min(best, float(np.degrees(np.arccos(np.clip(cos, -1, 1)))))
    return best


def test_summary_matches_the_frames(dataset):
    s = write_report(dataset)
    fr = _frames(dataset)
    assert s["progress"] == {"shards_planned": 3, "shards_committed": 3, "frames_planned": 36, "frames_committed": 36,
                             "shards_staged": 0, "frames_staged": 0, "complete": True}
    betas = {k[:8]: np.asarray(f["model"]["identity"]) for k, f in fr.items()}
    norms = sorted(np.linalg.norm(b) for b in betas.values())
    assert s["identities"]["count"] == 3
    assert s["identities"]["code_norm"]["median"] == pytest.approx(norms[1])
    assert s["identities"]["code_norm"]["max"] == pytest.approx(norms[2])
    assert s["expressions"]["count"] == 9
    assert s["expressions"]["kinds"] == {"neutral": 3, "preset": 3, "random": 3}
    assert s["expressions"]["presets"] == {"smile": 3}
    groups: dict[str, list] = {}
    for k, f in fr.items():
        groups.setdefault(k[:13], []).append(f["camera"])
    smallest = sorted(_brute_smallest_angle(c) for c in groups.values())
    assert s["cameras"]["smallest_pairwise_angle_deg"]["min"] == pytest.approx(smallest[0], abs=1e-6)
    assert s["cameras"]["smallest_pairwise_angle_deg"]["max"] == pytest.approx(smallest[-1], abs=1e-6)
    assert s["cameras"]["frames"] == 36
    assert s["assets"]["hair"] == {"present": 1.0, "styles": {"short": 3}}
    assert s["assets"]["glasses"]["present"] == pytest.approx(1 / 3)
    itas = sorted(float(individual_typology_angle(skin_albedo(0.05 + 0.1 * i, 0.02))) for i in range(3))
    assert s["skin_ita_deg"]["min"] == pytest.approx(itas[0]) and s["skin_ita_deg"]["max"] == pytest.approx(itas[2])
    assert s["render"]["attempts"] == 0 and s["render"]["frame_seconds"] is None  # no logs
    assert s["read"] == {"shards": 3, "frames": 36}
    json.dumps(s, allow_nan=False)
    sample = write_report(dataset, max_shards=2)
    assert sample["read"] == {"shards": 2, "frames": 24} and sample["identities"]["count"] == 2
    assert sample["progress"] == s["progress"]


def test_in_progress_and_logs(tmp_path):
    from synth.dataset.shards import open_dataset
    from tests.support import fake_frames

    exp = fake_frames.plan(n_shards=3, n_expr=1, n_views=4)
    ds = open_dataset(tmp_path / "ds", "f" * 64, exp)
    fake_frames.render_dataset(ds, shards=["shard_000000"])
    with ds.staging("shard_000001") as st:  # two frames staged, then the process "dies"
        for key in st.expected_keys[:2]:
            st.write_frame(key, *fake_frames.pixels(key), fake_frames.frame_json(key))
    run = tmp_path / "ds" / "logs" / "local-20260101T000000Z-1"
    run.mkdir(parents=True)
    keys = exp["shard_000000"]
    lines0 = ["Fra:1 Mem:1M | Synchronizing object | head", encode(Start(("shard_000000",), 1, "h")),
              "Fra:1 Mem:2M" + encode(Frame("shard_000000", keys[0], 9.0)),  # bpy left its line unended
              encode(Error("shard_000000", "the HDR file is missing"))]
    lines1 = [encode(Frame("shard_000000", k, 1.5 + n)) for n, k in enumerate(keys)]
    lines1.append(encode(Frame("shard_000001", exp["shard_000001"][0], 7.0)))  # staged only: not counted
    (run / "batch_000000.0.log").write_text("\n".join(lines0) + "\n")
    (run / "batch_000000.1.log").write_text("\n".join(lines1) + "\n")
    (run / "batch_000001.0.log").write_text(encode(BatchEnd(1, ("shard_000002",), 0, -9, "killed", False)) + "\n")
    out = tmp_path / "r.html"
    s = write_report(tmp_path / "ds", out)
    p = s["progress"]
    assert (p["shards_committed"], p["frames_committed"], p["frames_planned"]) == (1, 4, 12)
    assert (p["shards_staged"], p["frames_staged"], p["complete"]) == (1, 2, False)
    r = s["render"]
    assert (r["runs"], r["attempts"], r["retried_batches"], r["failed_attempts"]) == (1, 3, 1, 2)
    assert r["errors"] == [{"log": "local-20260101T000000Z-1/batch_000000.0.log", "message": "the HDR file is missing"}]
    assert r["frames_timed"] == 4  # the retry's times replace the first attempt's
    assert r["seconds_by_shard"] == {"shard_000000": pytest.approx(1.5 + 2.5 + 3.5 + 4.5)}
    assert r["frame_seconds"]["max"] == pytest.approx(4.5)
    assert out.is_file()


def test_html_is_one_file_with_every_figure(dataset, tmp_path):
    out = tmp_path / "report.html"
    write_report(dataset, out)
    page = out.read_text()
    imgs = re.findall(r'<img alt="([^"]*)" src="([^"]*)"', page)
    assert [a for a, _ in imgs] == [t for t, _ in plots.FIGURES] + ["contact sheet"]
    assert all(src.startswith("data:image/png;base64,") for _, src in imgs)
    assert "<script" not in page and "http://" not in page and "https://" not in page and "<link" not in page


def test_empty_dataset_reports_nothing_committed(tmp_path):
    from synth.dataset.shards import open_dataset
    from tests.support import fake_frames

    open_dataset(tmp_path / "ds", "f" * 64, fake_frames.plan(2, 1, 2))
    s = write_report(tmp_path / "ds", tmp_path / "r.html")
    assert s["progress"]["frames_committed"] == 0 and s["identities"]["count"] == 0
    assert "No committed shard yet" in (tmp_path / "r.html").read_text()


def test_cli(dataset, tmp_path):
    cmd = [sys.executable, "-m", "synth.cli.main", "report"]
    p = subprocess.run([*cmd, str(dataset), "--json"], capture_output=True, text=True, check=True)
    assert json.loads(p.stdout)["format"] == "synth-report/1"
    assert not (dataset / "report.html").exists()  # --json alone writes no page
    p = subprocess.run([*cmd, str(tmp_path / "nope")], capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and p.stderr.startswith("synth: error: dataset directory")
