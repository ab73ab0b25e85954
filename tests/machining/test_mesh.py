"""Surface mesh of the tri-dexel workpiece: closed, right volume and bounds, walls at the exact
dexel ends, vertex colours in GLB and PLY."""
import math

import numpy as np
import pytest
import trimesh

from simulate.machining.cutting import Spindle, load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.simulation import simulate_machining
from simulate.machining.surface_mesh import surface_mesh
from simulate.machining.tools import make_cutter
from simulate.machining.virtual_workpiece import VirtualWorkpiece, export_meshes


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
    assert sorted(p.name for p in paths) == ["surface_deflection.glb", "surface_deflection.ply"]
    assert not list(tmp_path.glob("*.tmp"))
    wp = vw.workpiece
    for p in paths:
        m = trimesh.load(p, force="mesh")
        assert len(m.faces) > 0
        np.testing.assert_allclose(m.bounds, [wp.lower, [0.03, 0.02, 0.01]], atol=1e-6)
        cols = np.asarray(m.visual.vertex_colors)
        assert cols.shape == (len(m.vertices), 4)
        assert len(np.unique(cols[:, :3], axis=0)) > 5   # a colour map, not one colour
    assert math.isfinite(trimesh.load(paths[1], force="mesh").volume)
