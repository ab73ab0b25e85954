"""PLY and GLB written with numpy: the GLB follows the glTF 2.0 binary layout (header, 4-byte aligned
JSON and BIN chunks, bounds on positions) and both files read back in trimesh with the same
vertices, faces, colours and texture."""
import io
import json
import struct

import numpy as np
import trimesh
from PIL import Image

from simulate.machining.mesh_files import GlbMesh, glb_bytes, ply_bytes

V = np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.02, 0], [0, 0, 0.03]], float)
F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
RGBA = np.array([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [10, 20, 30, 255]], np.uint8)


def _png(w=3, h=5):
    buf = io.BytesIO()
    Image.new("RGB", (w, h), (1, 2, 3)).save(buf, format="PNG")
    return buf.getvalue()


def test_glb_layout_and_read_back():
    quad = np.array([[0.1, 0, 0], [0.2, 0, 0], [0.2, 0, 0.1], [0.1, 0, 0.1]])
    data = glb_bytes([GlbMesh("part", V, F, rgba=RGBA),
                      GlbMesh("legend", quad, np.array([[0, 1, 2], [0, 2, 3]]),
                              uv=np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float), texture=_png())])
    magic, version, total = struct.unpack("<4sII", data[:12])
    assert (magic, version, total) == (b"glTF", 2, len(data))
    jlen, jtype = struct.unpack("<I4s", data[12:20])
    assert jtype == b"JSON" and jlen % 4 == 0
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack("<I4s", data[20 + jlen:28 + jlen])
    assert btype == b"BIN\0" and blen % 4 == 0 and 28 + jlen + blen == len(data)
    assert doc["buffers"][0]["byteLength"] == blen
    for view in doc["bufferViews"]:
        assert view["byteOffset"] % 4 == 0 and view["byteOffset"] + view["byteLength"] <= blen
    pos = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    np.testing.assert_allclose(pos["min"], V.min(axis=0), atol=1e-7)
    np.testing.assert_allclose(pos["max"], V.max(axis=0), atol=1e-7)
    scene = trimesh.load(io.BytesIO(data), file_type="glb")
    part = scene.geometry["part"]
    np.testing.assert_allclose(part.vertices, V, atol=1e-7)
    np.testing.assert_array_equal(part.faces, F)
    np.testing.assert_array_equal(np.asarray(part.visual.vertex_colors), RGBA)
    assert scene.geometry["legend"].visual.material.baseColorTexture.size == (3, 5)


def test_ply_read_back():
    m = trimesh.load(io.BytesIO(ply_bytes(V, F, RGBA)), file_type="ply", process=False)
    np.testing.assert_allclose(m.vertices, V, atol=1e-7)
    np.testing.assert_array_equal(m.faces, F)
    np.testing.assert_array_equal(np.asarray(m.visual.vertex_colors), RGBA)
    assert m.is_watertight and m.volume > 0     # outward faces: a positive volume, 1e-6 m^3 / 6
    np.testing.assert_allclose(m.volume, 0.01 * 0.02 * 0.03 / 6, rtol=1e-5)
