"""Binary PLY and glTF 2.0 (GLB) files of the coloured part, written with numpy alone.

Why not trimesh: importing it (it pulls scipy.spatial and scipy.optimize in) took about as long as
writing the files; ``greybench machine`` and every service pose write these two files. The layout
is what trimesh writes and reads back (tests load the files with trimesh):

- PLY (Turk 1994; binary_little_endian 1.0): float32 ``x y z``, uchar ``red green blue alpha`` per
  vertex, faces as ``list uchar int vertex_indices``.
- GLB (Khronos glTF 2.0 specification, section 4.4 "GLB File Format Specification"): a 12-byte
  header, a JSON chunk and a BIN chunk, each padded to 4 bytes. Positions float32 (VEC3, with the
  required min/max), indices uint32, vertex colours ``COLOR_0`` as normalised uint8 VEC4 (linear,
  as the specification defines them), texture coordinates float32 VEC2, an embedded PNG image.
"""
from __future__ import annotations

import json
import struct
from typing import NamedTuple

import numpy as np

#: glTF component types (specification 3.6.2.2) and buffer-view targets.
_FLOAT, _UINT8, _UINT32 = 5126, 5121, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def ply_bytes(vertices: np.ndarray, faces: np.ndarray, rgba: np.ndarray) -> bytes:
    """A binary PLY of a triangle mesh with RGBA vertex colours: ``vertices`` (V, 3) [m],
    ``faces`` (F, 3) vertex indices, ``rgba`` (V, 4) uint8."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(v)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
              f"element face {len(f)}\n"
              "property list uchar int vertex_indices\nend_header\n").encode("ascii")
    vert = np.empty(len(v), dtype=[("p", "<f4", 3), ("c", "u1", 4)])
    vert["p"] = v
    vert["c"] = np.asarray(rgba, np.uint8)[:, :4]
    face = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face["n"] = 3
    face["i"] = f
    return header + vert.tobytes() + face.tobytes()


class GlbMesh(NamedTuple):
    """One mesh (and node) of a GLB: ``name``, ``vertices`` (V, 3) [m], ``faces`` (F, 3); either
    ``rgba`` (V, 4) uint8 linear vertex colours, or ``uv`` (V, 2) with a PNG ``texture`` (bytes),
    shown double-sided and unlit-looking (metallic 0, roughness 1)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    rgba: np.ndarray | None = None
    uv: np.ndarray | None = None
    texture: bytes | None = None


class _Buffer:
    """The BIN chunk being assembled, with its buffer views and accessors."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.length = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.length) % 4
        if pad:
            self.parts.append(b"\0" * pad)
            self.length += pad
        v = {"buffer": 0, "byteOffset": self.length, "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.views.append(v)
        self.parts.append(data)
        self.length += len(data)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, component: int, kind: str, target: int, *, normalized: bool = False,
                 bounds: bool = False) -> int:
        acc = {"bufferView": self.view(np.ascontiguousarray(array).tobytes(), target), "componentType": component,
               "count": int(len(array)), "type": kind}
        if normalized:
            acc["normalized"] = True
        if bounds and len(array):
            acc["min"] = [float(x) for x in array.min(axis=0)]
            acc["max"] = [float(x) for x in array.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def glb_bytes(meshes: list[GlbMesh]) -> bytes:
    """A binary glTF 2.0 file with one node per mesh (module docstring)."""
    buf = _Buffer()
    doc: dict = {"asset": {"version": "2.0", "generator": "greybench"}, "scene": 0,
                 "scenes": [{"nodes": list(range(len(meshes)))}], "nodes": [], "meshes": []}
    for m in meshes:
        idx = buf.accessor(np.asarray(m.faces, "<u4").reshape(-1), _UINT32, "SCALAR", _ELEMENT_ARRAY_BUFFER)
        attrs = {"POSITION": buf.accessor(np.asarray(m.vertices, "<f4"), _FLOAT, "VEC3", _ARRAY_BUFFER,
                                          bounds=True)}
        prim: dict = {"attributes": attrs, "indices": idx, "mode": 4}
        if m.rgba is not None:
            attrs["COLOR_0"] = buf.accessor(np.asarray(m.rgba, np.uint8)[:, :4], _UINT8, "VEC4", _ARRAY_BUFFER,
                                            normalized=True)
        if m.uv is not None and m.texture is not None:
            attrs["TEXCOORD_0"] = buf.accessor(np.asarray(m.uv, "<f4"), _FLOAT, "VEC2", _ARRAY_BUFFER)
            image = {"bufferView": buf.view(m.texture), "mimeType": "image/png"}
            doc.setdefault("images", []).append(image)
            doc.setdefault("textures", []).append({"source": len(doc["images"]) - 1})
            doc.setdefault("materials", []).append(
                {"name": m.name, "doubleSided": True,
                 "pbrMetallicRoughness": {"baseColorTexture": {"index": len(doc["textures"]) - 1},
                                          "metallicFactor": 0.0, "roughnessFactor": 1.0}})
            prim["material"] = len(doc["materials"]) - 1
        doc["meshes"].append({"name": m.name, "primitives": [prim]})
        doc["nodes"].append({"name": m.name, "mesh": len(doc["meshes"]) - 1})
    binary = b"".join(buf.parts)
    binary += b"\0" * ((-len(binary)) % 4)
    doc["buffers"] = [{"byteLength": len(binary)}]
    doc["bufferViews"] = buf.views
    doc["accessors"] = buf.accessors
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * ((-len(js)) % 4)   # the JSON chunk is padded with spaces
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\0") + binary)
