"""The report page: one HTML file, figures embedded as ``data:image/png;base64`` URIs, no
scripts and no external resources, so it opens anywhere (and offline) as it is."""

from __future__ import annotations

import base64
import html
import tempfile
from pathlib import Path

from synth.report import plots

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #ddd; }
img { max-width: 100%; display: block; margin: 0.4em 0; }
table { border-collapse: collapse; font-size: 0.85em; } td, th { padding: 2px 10px; text-align: left; }
tr:nth-child(even) { background: #f4f4f4; } .muted { color: #777; } code { font-size: 0.9em; }
"""


def _img(png: bytes, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">'


def _table(rows) -> str:
    cells = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    return f"<table>{cells}</table>"


def _fmt(q: dict | None, unit: str = "") -> str:
    if not q:
        return "-"
    return (f"median {q['median']:.3g}{unit} (5-95%: {q['p5']:.3g}-{q['p95']:.3g}{unit}; "
            f"min {q['min']:.3g}, max {q['max']:.3g}; n = {q['n']})")


def contact_sheet_png(root: Path, shards: int = 8) -> bytes | None:
    """An overview contact sheet (synth.dataset.preview) of the first committed shards."""
    from synth.dataset.preview import overview_sheet
    from synth.errors import SynthError

    with tempfile.TemporaryDirectory(prefix="synth-report-") as tmp:
        p = Path(tmp) / "sheet.png"
        try:
            overview_sheet(root, p, views=4, max_shards=shards, tile=80, columns=2)
        except SynthError:  # nothing committed yet: the page says so
            return None
        return p.read_bytes()


def write_report(root, out=None, *, max_shards: int | None = None) -> dict:
    """Collect ``root`` (the first ``max_shards`` committed shards when given), write the page to
    ``out`` (atomically) when given; returns the JSON summary."""
    from synth.errors import SynthError
    from synth.io import atomic_write_bytes
    from synth.report.collect import collect

    collected = collect(root, max_shards=max_shards)
    summary = collected.summary()
    if out is not None:
        page = render_html(collected, summary, contact_sheet_png(Path(root)))
        try:
            atomic_write_bytes(Path(out), page.encode("utf-8"))
        except OSError as e:
            raise SynthError(f"cannot write the report ({e.strerror})", str(out), "pass -o with a writable path") \
                from None
    return summary


def render_html(collected, summary: dict, sheet: bytes | None) -> str:
    s = summary
    p = s["progress"]
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>synth report: "
             f"{html.escape(Path(s['dataset']).name)}</title><style>{STYLE}</style></head><body>",
             f"<h1>Dataset report: <code>{html.escape(s['dataset'])}</code></h1>",
             "<p class=\"muted\">Committed shards only; a dataset still rendering reports what is committed. "
             "The same numbers as JSON: <code>synth report DIR --json</code>.</p>",
             _table([("shards committed", f"{p['shards_committed']} / {p['shards_planned']}"),
                     ("read for this report", f"{s['read']['frames']} frames of {s['read']['shards']} shards"),
                     ("frames committed", f"{p['frames_committed']} / {p['frames_planned']}"),
                     ("staged (in progress)", f"{p['frames_staged']} frames in {p['shards_staged']} shards"),
                     ("identities", s["identities"]["count"]), ("expressions", s["expressions"]["count"]),
                     ("identity code norm", _fmt(s["identities"]["code_norm"])),
                     ("smallest view separation", _fmt(s["cameras"]["smallest_pairwise_angle_deg"], " deg")),
                     ("skin ITA", _fmt(s["skin_ita_deg"], " deg")),
                     ("visible landmarks per frame", _fmt(s["landmarks_visible_fraction"])),
                     ("render time per frame", _fmt(s["render"]["frame_seconds"], " s"))])]
    for title, fn in plots.FIGURES:
        parts.append(f"<h2>{html.escape(title)}</h2>")
        parts.append(_img(fn(collected), title))
        if title == "Failures and retries":
            errs = s["render"].get("errors") or []
            parts.append(_table([(e["log"], e["message"]) for e in errs]) if errs
                         else "<p class=\"muted\">No error events in the logs.</p>")
    parts.append("<h2>Contact sheet</h2>")
    parts.append(_img(sheet, "contact sheet") if sheet else "<p class=\"muted\">No committed shard yet.</p>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
