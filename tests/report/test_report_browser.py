"""The report in a real browser: headless Chromium loads it without console messages, decodes
every embedded figure, and takes a screenshot (Debian package ``chromium``; skipped without it).

A wrapper page loads the report in an iframe and logs how many of its images decoded
(``--allow-file-access-from-files`` lets it read the iframe); Chromium logs every console
message of both pages on stderr (``--enable-logging=stderr``), so any message other than the
wrapper's own line is a failure.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from synth.report import plots
from synth.report.html import write_report
from tests.support.datasets import model_dataset

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian: apt-get install chromium)")

WRAPPER = """<!DOCTYPE html><html><body><iframe id="r" src="report.html" style="width:1280px;height:9000px"></iframe>
<script>
document.getElementById('r').addEventListener('load', () => {
  const imgs = Array.from(document.getElementById('r').contentDocument.images);
  const bad = imgs.filter(i => !(i.complete && i.naturalWidth > 0));
  console.log('SYNTH-IMAGES ' + imgs.length + ' ' + bad.length);
});
</script></body></html>
"""


def chromium(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           "--enable-logging=stderr", "--v=0", *args], capture_output=True, text=True, timeout=120)


def console_messages(stderr: str) -> list[str]:
    return re.findall(r'INFO:CONSOLE[^\]]*\] "(.*?)", source: ', stderr)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser")
    ds, _ = model_dataset(root / "ds", identities=2, expressions=2, views=3)
    out = root / "report.html"
    write_report(ds, out)
    return out


def test_console_messages_are_seen(tmp_path):
    """The check below can fail: a page that logs an error is caught."""
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><body><script>console.error("boom")</script></body></html>')
    p = chromium("--dump-dom", page.as_uri())
    assert console_messages(p.stderr) == ["boom"]


def test_every_figure_decodes_without_console_messages(report):
    wrapper = report.parent / "wrapper.html"
    wrapper.write_text(WRAPPER)
    p = chromium("--allow-file-access-from-files", "--virtual-time-budget=10000", "--dump-dom", wrapper.as_uri())
    n = len(plots.FIGURES) + 1  # and the contact sheet
    assert console_messages(p.stderr) == [f"SYNTH-IMAGES {n} 0"], p.stderr[-2000:]


def test_screenshot(report, tmp_path):
    from PIL import Image

    shot = tmp_path / "shot.png"
    p = chromium("--window-size=1280,6000", f"--screenshot={shot}", report.as_uri())
    assert shot.is_file(), p.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB"))
    assert img.shape[:2] == (6000, 1280)
    assert console_messages(p.stderr) == []
    # the figures are there: many rows of the page are not plain background
    busy = (img.std(axis=(1, 2)) > 10).mean()
    assert busy > 0.3
