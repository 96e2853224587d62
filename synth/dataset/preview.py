"""``synth preview DIR``: a contact sheet of one shard (rows: expressions, columns: views).

Each cell shows three tiles side by side: colour (scene-linear -> sRGB, alpha composited over
mid grey), segmentation (palette of :mod:`synth.dataset.segmentation`) and depth (normalised over the
head: near = bright, far = dark, background black). An unreadable frame gets a red tile.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from synth.appearance.srgb import linear_to_srgb, srgb_to_linear
from synth.dataset.exr import read_frame_exr
from synth.dataset.layout import parse_frame_key, parse_frame_key_env
from synth.dataset.reader import FrameRef, list_frames
from synth.dataset.segmentation import PALETTE
from synth.dataset.shards import load_dataset
from synth.errors import SynthError
from synth.io import atomic_write_bytes

GREY_SRGB = 0.5
BG = (24, 24, 24)
LABEL = (220, 220, 220)


def colour_tile(rgba: np.ndarray) -> np.ndarray:
    """Premultiplied linear RGBA -> uint8 sRGB, over mid grey."""
    c = rgba.astype(np.float32)
    a = np.clip(c[..., 3:4], 0, 1)
    lin = c[..., :3] + (1 - a) * float(srgb_to_linear(GREY_SRGB))
    return (linear_to_srgb(lin) * 255 + 0.5).astype(np.uint8)


def seg_tile(seg: np.ndarray) -> np.ndarray:
    lut = np.full((max(PALETTE) + 2, 3), 255, np.uint8)  # unknown IDs: white
    for i, rgb in PALETTE.items():
        lut[i] = rgb
    return lut[np.minimum(seg, len(lut) - 1)]


def depth_tile(depth: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    fg = (alpha > 0) & np.isfinite(depth) & (depth > 0)
    out = np.zeros(depth.shape, np.float32)
    if fg.any():
        lo, hi = float(depth[fg].min()), float(depth[fg].max())
        out[fg] = 1.0 - 0.8 * (depth[fg] - lo) / max(hi - lo, 1e-6)  # near 1.0, far 0.2
    g = (out * 255 + 0.5).astype(np.uint8)
    return np.repeat(g[..., None], 3, axis=-1)


def _frame_tiles(ref: FrameRef, tile: int):
    """Colour, segmentation and depth tiles of one frame (a directory's or a tar shard's)."""
    from PIL import Image

    try:
        px = read_frame_exr(ref.exr_bytes(), verify=True, where=str(ref.json_path.with_suffix(".exr")))
    except (SynthError, OSError):
        bad = np.zeros((tile, tile, 3), np.uint8)
        bad[..., 0] = 160
        return [Image.fromarray(bad)] * 3
    h, w = px["height"], px["width"]
    size = (max(1, round(tile * w / h)), tile)
    alpha = px["rgba"][..., 3].astype(np.float32)
    imgs = [Image.fromarray(colour_tile(px["rgba"])).resize(size, Image.LANCZOS),
            Image.fromarray(seg_tile(px["segmentation"])).resize(size, Image.NEAREST),
            Image.fromarray(depth_tile(px["depth"], alpha)).resize(size, Image.NEAREST)]
    return imgs


def contact_sheet(root, shard_id: str | None = None, out=None, *, max_views: int | None = None,
                  tile: int = 96) -> Path:
    """Write a contact-sheet PNG of a committed shard (atomically); returns its path.

    Default shard: the first committed one. Default output: ``DIR/preview_<shard>.png``.
    """
    try:
        from PIL import Image, ImageDraw, ImageFont
    except ImportError as e:  # pragma: no cover
        raise SynthError("pillow is not installed", None, "install it: .venv/bin/pip install pillow") from e
    ds = load_dataset(root)
    committed = sorted(ds.committed_shards())
    if shard_id is None:
        if not committed:
            raise SynthError("the dataset has no committed shard yet", str(ds.root), "render at least one shard first")
        shard_id = committed[0]
    elif shard_id not in committed:
        hint = f"committed: {', '.join(committed[:3])}{', ...' if len(committed) > 3 else ''}" if committed \
            else "none is committed yet"
        raise SynthError(f"shard {shard_id} is not committed", str(ds.root), f"pass --shard with one that is ({hint})")
    if tile < 8:
        raise SynthError(f"tile size {tile} is too small", None, "use --tile 8 or more")
    manifest = ds.read_manifest(shard_id)
    keys = sorted(manifest["frames"])
    parsed = {k: (i, e, v) for k in keys for i, e, n, v in [parse_frame_key_env(k)] if n == 0}  # environment 0
    exprs = sorted({p[1] for p in parsed.values()})
    views = sorted({p[2] for p in parsed.values()})
    if max_views is not None:
        if max_views < 1:
            raise SynthError(f"--max-views {max_views} must be at least 1", None, "pass a positive number")
        views = views[:max_views]
    refs = {r.key: r for r in list_frames(ds.root, shards=[shard_id])}
    cells: dict[tuple[int, int], list] = {}
    for k, (_, e, v) in parsed.items():
        if v in views:
            cells[(e, v)] = _frame_tiles(refs[k], tile)
    tw = max((t[0].size[0] for t in cells.values()), default=tile)
    gap, pad, label_w, label_h = 2, 8, 44, 16
    cell_w = 3 * tw + 2 * gap
    W = label_w + len(views) * (cell_w + pad) + pad
    H = label_h * 2 + len(exprs) * (tile + pad) + pad
    sheet = Image.new("RGB", (W, H), BG)
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    ids = sorted({p[0] for p in parsed.values()})
    draw.text((pad, 2), f"{shard_id}  identity {', '.join(map(str, ids))}  ({len(keys)} frames; "
                        f"colour | segmentation | depth)", fill=LABEL, font=font)
    for j, v in enumerate(views):
        draw.text((label_w + j * (cell_w + pad), label_h + 2), f"v{v:02d}", fill=LABEL, font=font)
    for i, e in enumerate(exprs):
        y = 2 * label_h + i * (tile + pad)
        draw.text((4, y + tile // 2 - 6), f"ex{e:02d}", fill=LABEL, font=font)
        for j, v in enumerate(views):
            x = label_w + j * (cell_w + pad)
            for t, im in enumerate(cells.get((e, v), [])):
                sheet.paste(im, (x + t * (tw + gap), y))
    out = Path(out) if out is not None else ds.root / f"preview_{shard_id}.png"
    return _save_png(sheet, out)


def overview_sheet(root, out=None, *, views: int = 3, max_shards: int | None = None, tile: int = 96,
                   columns: int = 2) -> Path:
    """Many identities at a glance: for each committed shard (in order), its first identity's
    first expression at up to ``views`` views, colour and segmentation side by side; shards
    laid out in ``columns`` columns. Default output: ``DIR/overview.png``."""
    from PIL import Image, ImageDraw, ImageFont

    ds = load_dataset(root)
    committed = sorted(ds.committed_shards())
    if not committed:
        raise SynthError("the dataset has no committed shard yet", str(ds.root), "render at least one shard first")
    if views < 1 or tile < 8 or columns < 1:
        raise SynthError("--views, --tile and --columns must be positive (tile >= 8)", None, "pass sensible sizes")
    shards = committed[:max_shards] if max_shards else committed
    rows = []
    for sid in shards:
        refs = list_frames(ds.root, shards=[sid])
        parsed = [(r, parse_frame_key(r.key)) for r in refs]
        i0 = min(p[0] for _, p in parsed)
        e0 = min(p[1] for _, p in parsed if p[0] == i0)
        sel = [r for r, p in parsed if p[0] == i0 and p[1] == e0][:views]
        rows.append((sid, i0, [_frame_tiles(r, tile)[:2] for r in sel]))
    tw = max(t[0].size[0] for _, _, r in rows for t in r)
    gap, pad, label_h = 2, 8, 14
    block_w = views * (2 * tw + gap + pad)
    block_h = label_h + tile + pad
    ncol = min(columns, len(rows))
    nrow = -(-len(rows) // ncol)
    sheet = Image.new("RGB", (pad + ncol * (block_w + pad), pad + nrow * block_h), BG)
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for n, (sid, ident, cells) in enumerate(rows):
        x0 = pad + (n % ncol) * (block_w + pad)
        y0 = pad + (n // ncol) * block_h
        draw.text((x0, y0), f"identity {ident} ({sid})", fill=LABEL, font=font)
        for j, tiles in enumerate(cells):
            x = x0 + j * (2 * tw + gap + pad)
            for t, im in enumerate(tiles):
                sheet.paste(im, (x + t * (tw + gap), y0 + label_h))
    out = Path(out) if out is not None else ds.root / "overview.png"
    return _save_png(sheet, out)


def _save_png(sheet, out: Path) -> Path:
    buf = io.BytesIO()
    sheet.save(buf, format="PNG")
    try:
        atomic_write_bytes(out, buf.getvalue())
    except OSError as e:
        raise SynthError(f"cannot write the preview ({e.strerror})", str(out), "pass -o with a writable path") from None
    return out
