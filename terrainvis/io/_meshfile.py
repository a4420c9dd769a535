"""Terrains as mesh files: ``.ply``, ``.obj``, ``.stl`` and ``.glb`` (written here, read with trimesh)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..core.fileio import atomic_path
from ..core.terrain import TIN, HeightGrid
from ..tolerances import DIVISOR_FLOOR, FLOAT32_ROUNDING_REL
from ._attrs import _attrs_from_json, _attrs_to_json
from ._common import FORMAT, FORMAT_VERSION, _TIN_ORIENTATION, _Corrupt

_PLY_ATTRS = "comment terrainvis-attrs "
_OBJ_ATTRS = "# terrainvis-attrs "


def _mesh_of(terrain) -> TIN:
    return terrain.to_tin() if isinstance(terrain, HeightGrid) else terrain


def _ply_bytes(tin: TIN, attrs_json: str) -> bytes:
    faces = tin.faces
    index_type, index_dtype = ("int", "<i4") if tin.n_vertices < 2**31 else ("uint", "<u4")
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"{_PLY_ATTRS}{attrs_json}\n"
        f"element vertex {tin.n_vertices}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {tin.n_faces}\nproperty list uchar {index_type} vertex_indices\nend_header\n"
    )
    packed = np.empty(tin.n_faces, dtype=[("n", "u1"), ("i", index_dtype, (3,))])
    packed["n"] = 3
    packed["i"] = faces
    return header.encode("ascii") + tin.vertices.astype("<f8").tobytes() + packed.tobytes()


def _obj_bytes(tin: TIN, attrs_json: str) -> bytes:
    import io

    buf = io.StringIO()
    buf.write(f"# terrainvis {FORMAT_VERSION}: a TIN, x y z as written (z up), faces counter-clockwise from above\n")
    buf.write(f"{_OBJ_ATTRS}{attrs_json}\n")
    np.savetxt(buf, tin.vertices, fmt="v %.17g %.17g %.17g")
    np.savetxt(buf, tin.faces.astype(np.int64) + 1, fmt="f %d %d %d")
    return buf.getvalue().encode("ascii")


def _stl_bytes(tin: TIN) -> bytes:
    import trimesh

    v = tin.vertices
    err = float(np.abs(v.astype(np.float32).astype(np.float64) - v).max())
    lo, hi = v.min(axis=0), v.max(axis=0)
    span = float((hi - lo).max())
    if err > FLOAT32_ROUNDING_REL * max(span, DIVISOR_FLOOR):
        warnings.warn(
            f"STL stores float32: coordinates up to {np.abs(v).max():.6g} are rounded by up to {err:.3g} "
            f"({err / max(span, DIVISOR_FLOOR):.2g} of the terrain's extent); save to .ply, .obj or .npz for exact coordinates",
            UserWarning, stacklevel=4,
        )
    mesh = trimesh.Trimesh(vertices=v, faces=tin.faces, process=False, validate=False)
    return mesh.export(file_type="stl")


def _glb_bytes(tin: TIN, attrs_json: str) -> bytes:
    import trimesh

    origin = tin.vertices.min(axis=0)
    mesh = trimesh.Trimesh(vertices=tin.vertices - origin, faces=tin.faces, process=False, validate=False)
    scene = trimesh.Scene()
    transform = np.eye(4)
    transform[:3, 3] = origin
    scene.add_geometry(mesh, node_name="terrain", geom_name="terrain", transform=transform)
    scene.metadata["terrainvis"] = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "kind": "tin", "orientation": _TIN_ORIENTATION,
        "origin": [float(v) for v in origin], "attrs": attrs_json,
    }
    return scene.export(file_type="glb")


def _write_mesh(terrain, p: Path, suffix: str) -> None:
    tin = _mesh_of(terrain)
    if suffix == ".stl":
        if terrain.attrs:
            keys = sorted(k for k in terrain.attrs if k != "path")
            if keys:
                warnings.warn(
                    f"STL has no place for metadata: attrs {keys} are not written", UserWarning, stacklevel=3,
                )
        data = _stl_bytes(tin)
    else:
        attrs_json = _attrs_to_json(terrain.attrs)
        data = {".ply": _ply_bytes, ".obj": _obj_bytes, ".glb": _glb_bytes}[suffix](tin, attrs_json)
    with atomic_path(p) as tmp:
        tmp.write_bytes(data)


def _ply_header(p: Path) -> list[str]:
    """The lines of a PLY file's header (before ``end_header``)."""
    with open(p, "rb") as fh:
        head = b""
        while b"end_header" not in head:
            chunk = fh.read(1 << 16)
            if not chunk:
                break
            head += chunk
    return head.split(b"end_header")[0].decode("ascii", errors="replace").splitlines()


def _check_ply_counts(p: Path, n_vertices: int, n_faces: int) -> None:
    """The vertices and faces read are the ones a PLY's header declares: trimesh read the face
    lines of an ASCII file that holds fewer vertices than it declares as vertices, and such a
    mesh was measured (and repaired) as if it were whole."""
    declared = {}
    for line in _ply_header(p):
        words = line.split()
        if len(words) == 3 and words[0] == "element" and words[1] in ("vertex", "face") and words[2].isdigit():
            declared[words[1]] = int(words[2])
    nv, nf = declared.get("vertex"), declared.get("face")
    # a polygon is read as triangles: at least as many faces as declared, never fewer
    if (nv is not None and nv != n_vertices) or (nf is not None and n_faces < nf):
        raise _Corrupt(f"its header declares {nv} vertices and {nf} faces, but {n_vertices} vertices and {n_faces} "
                       "faces were read: the file is cut off or damaged")


def _mesh_attrs(p: Path, suffix: str, loaded) -> dict:
    if suffix == ".ply":
        for line in _ply_header(p):
            if line.startswith(_PLY_ATTRS):
                return _attrs_from_json(line[len(_PLY_ATTRS):])
    elif suffix == ".obj":
        with open(p, "r", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                if line.startswith(_OBJ_ATTRS):
                    return _attrs_from_json(line[len(_OBJ_ATTRS):].strip())
    elif suffix == ".glb":
        meta = getattr(loaded, "metadata", {}) or {}
        info = meta.get("terrainvis")
        if isinstance(info, dict) and isinstance(info.get("attrs"), str):
            return _attrs_from_json(info["attrs"])
    return {}


def _read_mesh(p: Path, suffix: str) -> TIN:
    import trimesh

    try:
        loaded = trimesh.load(str(p), file_type=suffix[1:], process=False)
        mesh = loaded.to_geometry() if isinstance(loaded, trimesh.Scene) else loaded
    except Exception as exc:  # a third-party parser: any failure means the file cannot be read
        raise _Corrupt(f"trimesh could not read it ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise _Corrupt(f"it holds no triangle mesh (trimesh read {type(mesh).__name__})")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if suffix == ".ply":
        _check_ply_counts(p, vertices.shape[0], faces.shape[0])
    if suffix == ".stl":
        # STL repeats each vertex for every face: merge exact duplicates.
        vertices, inverse = np.unique(vertices, axis=0, return_inverse=True)
        faces = inverse.reshape(-1)[faces]
    attrs = _mesh_attrs(p, suffix, loaded)
    return TIN(vertices, faces, attrs=attrs)
