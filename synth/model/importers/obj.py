"""A small, fast Wavefront OBJ reader for model import (``v``, ``vt``, ``f`` only).

Two entry points:

* :func:`read_obj` parses positions, texture coordinates, polygons (``f`` corners in
  any of the forms ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``, negative indices allowed) and
  the group (``g``) each polygon belongs to. Polygons are kept as written (quads stay
  quads, as ``poly_offsets``/``poly_indices``) and also fan-triangulated. Normals (``vn``),
  materials and everything else are ignored.
* :func:`read_obj_vertices` parses only the ``v`` lines, for the many shape files of a
  blend-shape model that share one topology (the text is filtered and handed to numpy's
  C parser in one call; ~10x faster than a line-by-line Python parse).

Errors are :class:`synth.errors.ModelFormatError` naming the file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from synth.errors import ModelFormatError

_FIX = "the file must be a Wavefront OBJ with 'v' and 'f' lines"


@dataclass
class ObjMesh:
    vertices: np.ndarray  # (V, 3) float64, as written
    poly_offsets: np.ndarray  # (P+1,) int32
    poly_indices: np.ndarray  # (N,) int32, 0-based vertex indices
    triangles: np.ndarray  # (T, 3) int32, fan triangulation of the polygons
    tri_poly: np.ndarray  # (T,) int32, polygon each triangle came from
    uvs: np.ndarray | None = None  # (U, 2) float32
    poly_uv: np.ndarray | None = None  # (N,) int32 parallel to poly_indices
    tri_uv: np.ndarray | None = None  # (T, 3) int32
    poly_group: np.ndarray | None = None  # (P,) int32 index into group_names
    group_names: list[str] | None = None  # 'g' names in order of first use ("" before any 'g' line)


def _read_bytes(path: Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except FileNotFoundError:
        raise ModelFormatError("OBJ file not found", str(path), "check the path") from None
    except OSError as e:
        raise ModelFormatError(f"cannot read OBJ file ({e.strerror or e})", str(path), "check permissions") from None


def _floats(lines: list[bytes], ncol: int, what: str, path: Path) -> np.ndarray:
    """Parse lines of whitespace-separated numbers (prefix already stripped) into (n, ncol)."""
    n = len(lines)
    if n == 0:
        return np.zeros((0, ncol))
    text = b" ".join(lines)
    try:
        flat = np.fromstring(text, dtype=np.float64, sep=" ")  # text mode: C parser, not deprecated
    except ValueError:
        flat = np.zeros(0)
    if flat.size == n * ncol:
        out = flat.reshape(n, ncol)
    else:  # extra columns (v x y z w, vertex colours) or junk: slow, exact path
        out = np.empty((n, ncol))
        for i, ln in enumerate(lines):
            parts = ln.split()
            try:
                out[i] = [float(p) for p in parts[:ncol]]
            except ValueError:
                raise ModelFormatError(f"malformed '{what}' line {i + 1}: {ln[:60]!r}", str(path), _FIX) from None
            if len(parts) < ncol:
                raise ModelFormatError(f"'{what}' line {i + 1} has {len(parts)} numbers, needs {ncol}",
                                       str(path), _FIX)
    if not np.all(np.isfinite(out)):
        raise ModelFormatError(f"'{what}' values contain NaN or Inf", str(path), _FIX)
    return out


def read_obj_vertices(path: str | Path) -> np.ndarray:
    """(V, 3) float64 positions from the ``v`` lines only."""
    path = Path(path)
    data = _read_bytes(path)
    # fast path: the 'v' lines form one block (as every exporter writes them)
    first = 0 if data.startswith(b"v ") else data.find(b"\nv ") + 1
    if first > 0 or data.startswith(b"v "):
        last = data.rfind(b"\nv ")
        end = data.find(b"\n", max(last, first) + 1)
        block = data[first:end if end >= 0 else len(data)]
        nlines = block.count(b"\n") + 1
        if block.count(b"\nv ") == nlines - 1:
            flat = np.fromstring(block.replace(b"v ", b" "), dtype=np.float64, sep=" ")
            if flat.size == 3 * nlines and np.all(np.isfinite(flat)):
                return flat.reshape(nlines, 3)
    lines = [ln[2:] for ln in data.split(b"\n") if ln[:2] in (b"v ", b"v\t")]
    if not lines:
        raise ModelFormatError("no vertex ('v') lines", str(path), _FIX)
    return _floats(lines, 3, "v", path)


def read_obj(path: str | Path) -> ObjMesh:
    """Positions, UVs and polygons (kept and triangulated). See the module docstring."""
    path = Path(path)
    data = _read_bytes(path)
    vlines: list[bytes] = []
    tlines: list[bytes] = []
    flines: list[bytes] = []
    fgroup: list[int] = []
    groups: dict[bytes, int] = {}
    group = b""
    for ln in data.split(b"\n"):
        head = ln[:3]
        if head[:2] in (b"v ", b"v\t"):
            vlines.append(ln[2:])
        elif head in (b"vt ", b"vt\t"):
            tlines.append(ln[3:])
        elif head[:2] in (b"f ", b"f\t"):
            flines.append(ln[2:])
            fgroup.append(groups.setdefault(group, len(groups)))
        elif head[:2] in (b"g ", b"g\t"):
            group = ln[2:].strip()
    if not vlines:
        raise ModelFormatError("no vertex ('v') lines", str(path), _FIX)
    if not flines:
        raise ModelFormatError("no face ('f') lines", str(path), _FIX)
    verts = _floats(vlines, 3, "v", path)
    uvs = _floats(tlines, 2, "vt", path) if tlines else None
    nv, nt = verts.shape[0], 0 if uvs is None else uvs.shape[0]

    counts = np.empty(len(flines), np.int64)
    vi: list[int] = []
    ti: list[int] = []
    has_uv = uvs is not None
    for p, ln in enumerate(flines):
        corners = ln.split()
        counts[p] = len(corners)
        try:
            for c in corners:
                parts = c.split(b"/")
                vi.append(int(parts[0]))
                if has_uv:
                    ti.append(int(parts[1]) if len(parts) > 1 and parts[1] else 0)
        except ValueError:
            raise ModelFormatError(f"malformed face line {p + 1}: {ln[:60]!r}", str(path), _FIX) from None
    if np.any(counts < 3):
        p = int(np.argmax(counts < 3))
        raise ModelFormatError(f"face {p + 1} has fewer than 3 corners", str(path), _FIX)
    pv = np.asarray(vi, np.int64)
    pv = np.where(pv < 0, pv + nv, pv - 1)  # OBJ: 1-based, negative = relative to the end
    if pv.min() < 0 or pv.max() >= nv:
        raise ModelFormatError(f"face references vertex outside 1..{nv}", str(path), _FIX)
    pt = None
    if has_uv:
        pt = np.asarray(ti, np.int64)
        if np.any(pt == 0):  # some corners without UVs: drop UVs altogether
            pt, uvs = None, None
        else:
            pt = np.where(pt < 0, pt + nt, pt - 1)
            if pt.min() < 0 or pt.max() >= nt:
                raise ModelFormatError(f"face references texture coordinate outside 1..{nt}", str(path), _FIX)

    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    # fan triangulation: polygon p with corners c0..c(n-1) -> (c0, ck, ck+1), k = 1..n-2
    ntri = counts - 2
    tri_poly = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    base = offsets[:-1][tri_poly]
    corner = np.stack([base, base + k + 1, base + k + 2], axis=1)
    mesh = ObjMesh(
        vertices=verts,
        poly_offsets=offsets.astype(np.int32),
        poly_indices=pv.astype(np.int32),
        triangles=pv[corner].astype(np.int32),
        tri_poly=tri_poly.astype(np.int32),
        poly_group=np.asarray(fgroup, np.int32),
        group_names=[g.decode("utf-8", "replace") for g in groups],
    )
    if pt is not None:
        mesh.uvs = uvs.astype(np.float32)
        mesh.poly_uv = pt.astype(np.int32)
        mesh.tri_uv = pt[corner].astype(np.int32)
    return mesh
