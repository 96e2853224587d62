"""Mesh export (OBJ with UVs, binary PLY). Files are written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from synth.io import atomic_write_bytes


def obj_bytes(vertices: np.ndarray, triangles: np.ndarray, uvs: np.ndarray | None = None,
              tri_uv: np.ndarray | None = None, poly_offsets: np.ndarray | None = None,
              poly_indices: np.ndarray | None = None, poly_uv: np.ndarray | None = None) -> bytes:
    """Wavefront OBJ text. Polygons (quads kept) are written when given, else triangles."""
    lines = ["# written by synth"]
    v = np.asarray(vertices, np.float64)
    lines.append("\n".join("v %.6f %.6f %.6f" % tuple(p) for p in v))
    have_uv = uvs is not None
    if have_uv:
        lines.append("\n".join("vt %.6f %.6f" % tuple(t) for t in np.asarray(uvs, np.float64)))
    if poly_offsets is not None and poly_indices is not None:
        faces = []
        use_uv = have_uv and poly_uv is not None
        for a, b in zip(poly_offsets[:-1], poly_offsets[1:]):
            idx = poly_indices[a:b] + 1
            if use_uv:
                faces.append("f " + " ".join(f"{i}/{t}" for i, t in zip(idx, poly_uv[a:b] + 1)))
            else:
                faces.append("f " + " ".join(str(i) for i in idx))
        lines.append("\n".join(faces))
    else:
        t = np.asarray(triangles) + 1
        if have_uv and tri_uv is not None:
            tu = np.asarray(tri_uv) + 1
            lines.append("\n".join(f"f {a}/{ua} {b}/{ub} {c}/{uc}" for (a, b, c), (ua, ub, uc) in zip(t, tu)))
        else:
            lines.append("\n".join("f %d %d %d" % tuple(f) for f in t))
    return ("\n".join(lines) + "\n").encode()


def ply_bytes(vertices: np.ndarray, triangles: np.ndarray) -> bytes:
    """Binary little-endian PLY with float32 vertices and uint8-counted int32 faces."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    t = np.asarray(triangles, dtype="<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by synth\n"
        f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(t)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    faces = np.empty(len(t), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = t
    return header + v.tobytes() + faces.tobytes()


def write_mesh(path: str | Path, vertices: np.ndarray, model_data=None, triangles=None) -> Path:
    """Write OBJ (with the model's polygons and UVs) or PLY, chosen by the suffix."""
    path = Path(path)
    tris = triangles if triangles is not None else model_data.triangles
    if path.suffix.lower() == ".ply":
        data = ply_bytes(vertices, tris)
    elif path.suffix.lower() == ".obj":
        if model_data is not None:
            data = obj_bytes(vertices, tris, model_data.uvs, model_data.tri_uv, model_data.poly_offsets,
                             model_data.poly_indices, model_data.poly_uv)
        else:
            data = obj_bytes(vertices, tris)
    else:
        raise ValueError(f"unsupported mesh format {path.suffix!r}; use .obj or .ply")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, data)
    return path
