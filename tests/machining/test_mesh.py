"""Surface mesh of the tri-dexel workpiece: closed, right volume and bounds, walls at the exact
dexel ends, vertex colours in GLB and PLY."""
import io
import math

import matplotlib
import numpy as np
import pytest
import trimesh
from PIL import Image

from simulate.machining.cutting import Spindle, load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.simulation import simulate_machining
from simulate.machining.surface_mesh import _greedy_rectangles, surface_mesh
from simulate.machining.tools import make_cutter
from simulate.machining.virtual_workpiece import VirtualWorkpiece, coloured_mesh, export_meshes


@pytest.mark.parametrize("stride", [1, 2])
def test_box_meshes_to_a_closed_volume(stride):
    lo, hi = np.array([0.0013, -0.002, 0.0]), np.array([0.0213, 0.0151, 0.0087])
    wp = TriDexel.box(lo, hi, 0.5e-3)
    sm = surface_mesh(wp, stride=stride)
    m = sm.trimesh()
    assert len(m.faces) > 0
    assert m.is_watertight and m.is_winding_consistent and m.is_volume
    exact = float(np.prod(hi - lo))
    assert m.volume == pytest.approx(exact, rel=0.03)
    # faces of the box sit at the exact (off-grid) box coordinates
    np.testing.assert_allclose(m.bounds, [lo, hi], atol=1e-12)


def _pocketed(spacing=0.5e-3):
    wp = TriDexel.box([0, 0, 0], [0.03, 0.02, 0.01], spacing)
    n = 60
    x = np.linspace(-0.006, 0.036, n)
    xyz = np.column_stack([x, np.full(n, 0.0101), np.full(n, 0.007)])
    C = np.broadcast_to(np.eye(3) * 2e-7, (n, 3, 3))
    res = simulate_machining(wp, make_cutter("flat", 8e-3), np.arange(n) * 0.002, np.arange(n), xyz,
                             load_material("Al7075"), Spindle.from_rpm(12000), compliance=C)
    return VirtualWorkpiece(wp, res.steps)


def test_machined_slot_walls_at_dexel_ends():
    vw = _pocketed()
    sm = surface_mesh(vw.workpiece, stride=1)
    m = sm.trimesh()
    assert m.is_watertight and m.is_volume
    # slot walls y = 10.1 -+ 4 mm (+ deflection): a wall vertex is the mean of its cell's crossings,
    # which are y-ray ends: it lies within the range of the machined ends of the rays around it
    pts, step, _ = vw.workpiece.ends(1)
    pts = pts[step >= 0]
    s = vw.workpiece.spacing
    v = sm.vertices
    wall = (np.abs(np.abs(v[:, 1] - 0.0101) - 4e-3) < 0.5e-3) & (v[:, 2] > 0.0075) & (v[:, 2] < 0.0095) \
        & (v[:, 0] > 0.005) & (v[:, 0] < 0.025)
    assert wall.sum() > 20
    for p in v[wall]:
        near = (np.abs(pts[:, 0] - p[0]) <= s) & (np.abs(pts[:, 2] - p[2]) <= s) & (np.abs(pts[:, 1] - p[1]) < 0.5e-3)
        ys = pts[near, 1]
        assert len(ys) > 0
        assert ys.min() - 1e-12 <= p[1] <= ys.max() + 1e-12
    assert np.all(sm.vertex_step[wall] >= 0)
    # volume: the mesh against the dexel volume (slot is machined)
    assert m.volume == pytest.approx(vw.workpiece.volume(), rel=0.03)


def test_glb_and_ply_load_back_with_colours(tmp_path):
    vw = _pocketed()
    paths = export_meshes(vw, tmp_path, "deflection")
    assert sorted(p.name for p in paths) == ["surface_deflection.glb", "surface_deflection.ply",
                                             "surface_deflection_legend.png"]
    assert not list(tmp_path.glob("*.tmp"))
    wp = vw.workpiece
    glb = trimesh.load(tmp_path / "surface_deflection.glb")  # a scene: the part and its legend
    assert set(glb.geometry) == {"part", "legend"}
    ply = trimesh.load(tmp_path / "surface_deflection.ply", force="mesh")
    for m in (glb.geometry["part"], ply):
        assert len(m.faces) > 0
        np.testing.assert_allclose(m.bounds, [wp.lower, [0.03, 0.02, 0.01]], atol=1e-6)
        cols = np.asarray(m.visual.vertex_colors)
        assert cols.shape == (len(m.vertices), 4)
        assert len(np.unique(cols[:, :3], axis=0)) > 5   # a colour map, not one colour
    assert math.isfinite(ply.volume)
    # glTF vertex colours are linear: encoded back to sRGB they are the PLY's (sRGB) colours
    part = glb.geometry["part"]
    np.testing.assert_array_equal(part.vertices, ply.vertices)
    lin = np.asarray(part.visual.vertex_colors)[:, :3] / 255.0
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055) * 255.0
    dark = np.asarray(ply.visual.vertex_colors)[:, :3] > 40   # linear uint8 is coarse near black
    assert np.abs(srgb - np.asarray(ply.visual.vertex_colors)[:, :3])[dark].max() <= 3.0
    # the legend: a textured rectangle in the GLB, the same image beside it
    legend = glb.geometry["legend"]
    image = legend.visual.material.baseColorTexture
    png = (tmp_path / "surface_deflection_legend.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and image.size == Image.open(io.BytesIO(png)).size
    assert legend.bounds[0][0] > wp.upper[0]   # beside the part, not in it


def test_colour_scale_covers_the_machined_surface():
    vw = _pocketed()
    mesh, vals, (lo, hi) = coloured_mesh(vw, "deflection", stride=1, merge=False)
    ok = np.isfinite(vals)
    assert ok.sum() > 50
    # every machined vertex inside the scale: the ends are its extremes, no colour clipped
    assert lo == pytest.approx(vals[ok].min()) and hi == pytest.approx(vals[ok].max())
    # each colour decodes back to its value: no part of the machined surface is clipped to an end
    cols = np.asarray(mesh.visual.vertex_colors)[ok, :3].astype(float)
    lut = np.round(matplotlib.colormaps["viridis"](np.linspace(0, 1, 256))[:, :3] * 255)
    level = np.argmin(((cols[:, None, :] - lut[None]) ** 2).sum(axis=2), axis=1) / 255.0
    np.testing.assert_allclose(level, (vals[ok] - lo) / (hi - lo), atol=2.5 / 255)  # 256 levels
    assert (np.asarray(mesh.visual.vertex_colors)[~ok] == (200, 200, 200, 255)).all()


def test_merging_flat_quads_keeps_surface_and_colours():
    vw = _pocketed()
    full, _, (lo, hi) = coloured_mesh(vw, "deflection", stride=1, merge=False)
    merged, _, scale = coloured_mesh(vw, "deflection", stride=1, merge=True)
    assert scale == (lo, hi)
    assert len(merged.faces) < 0.5 * len(full.faces)
    assert merged.is_winding_consistent
    assert merged.volume == pytest.approx(full.volume, rel=1e-9)
    assert merged.area == pytest.approx(full.area, rel=1e-9)
    np.testing.assert_allclose(merged.bounds, full.bounds, atol=1e-15)

    def area_per_colour(m):
        cols = np.asarray(m.visual.vertex_colors)[m.faces]        # (F, 3, 4)
        one = (cols == cols[:, :1]).all(axis=(1, 2))
        assert one.mean() > 0.5
        key = cols[:, 0].astype(np.int64) @ np.array([1 << 24, 1 << 16, 1 << 8, 1])
        total = {}
        for k, a in zip(key[one], m.area_faces[one], strict=False):
            total[k] = total.get(k, 0.0) + a
        return total, m.area_faces[~one].sum()

    # the colour pattern: the area of every single-coloured region and of the mixed faces is unchanged
    a_full, mixed_full = area_per_colour(full)
    a_merged, mixed_merged = area_per_colour(merged)
    assert set(a_full) == set(a_merged)
    for k in a_full:
        assert a_merged[k] == pytest.approx(a_full[k], rel=1e-9, abs=1e-15)
    assert mixed_merged == pytest.approx(mixed_full, rel=1e-9)
    # every vertex kept is an original vertex with its original colour
    lookup = {tuple(v): tuple(c) for v, c in zip(full.vertices, np.asarray(full.visual.vertex_colors), strict=False)}
    for v, c in zip(merged.vertices, np.asarray(merged.visual.vertex_colors), strict=False):
        assert lookup[tuple(v)] == tuple(c)


def test_greedy_rectangles_cover_exactly_once():
    rng = np.random.default_rng(5)
    occ = rng.random((40, 30)) < 0.7
    occ[5:25, 3:20] = True
    rects = _greedy_rectangles(occ)
    cover = np.zeros(occ.shape, int)
    for i0, j0, i1, j1 in rects:
        cover[i0:i1, j0:j1] += 1
    np.testing.assert_array_equal(cover, occ.astype(int))
    assert len(rects) < occ.sum() / 2


def test_export_coarsens_a_large_part_to_its_node_budget(tmp_path, monkeypatch):
    """A part whose lattice exceeds EXPORT_MAX_NODES is exported at the smallest stride within it:
    the mesh shrinks by the square of the stride (a flat-topped box: its faces), the files get the
    mode the umask gives a new file."""
    import os

    from simulate.machining import surface_mesh as smod

    vw = _pocketed()
    n = int(np.prod(vw.workpiece.shape))
    full = export_meshes(vw, tmp_path / "full", "deflection", stride=1)
    monkeypatch.setattr(smod, "EXPORT_MAX_NODES", n // 7)   # (nx/2+3)(ny/2+3)(nz/2+3) > n/8 for this part
    old = os.umask(0o022)
    try:
        coarse = export_meshes(vw, tmp_path / "coarse", "deflection")
    finally:
        os.umask(old)
    assert smod.choose_stride(vw.workpiece.shape, n // 7) == 3
    f_full = len(trimesh.load(full[1], force="mesh").faces)
    f_coarse = len(trimesh.load(coarse[1], force="mesh").faces)
    assert f_coarse < f_full / 4
    assert all(p.stat().st_mode & 0o777 == 0o644 for p in coarse)
