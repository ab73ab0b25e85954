"""The Pillow figures of the virtual workpiece: the z-buffer keeps the nearest surface, a triangle
covers its own area in pixels, the top view shows each pixel's highest point, ticks are round."""
import numpy as np
import pytest

from simulate.machining.raster_figure import nice_ticks, raster_triangles, top_view


def test_triangle_covers_its_area_and_the_nearer_one_wins():
    # a right triangle of legs 100 px: 5000 px^2 (pixel centres inside it, +- one edge of pixels)
    xy = np.array([[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]]])
    img = raster_triangles(xy, np.zeros((1, 3)), np.array([[255, 0, 0]], np.uint8), 120, 120)
    red = (img == [255, 0, 0]).all(axis=2).sum()
    assert abs(red - 5000) <= 101
    # two overlapping squares' halves at different depths, drawn far first and near first
    sq = np.array([[[10.0, 10.0], [60.0, 10.0], [10.0, 60.0]]])
    for order in ([0, 1], [1, 0]):
        tri = np.concatenate([sq, sq])[order]
        depth = np.array([[5.0] * 3, [1.0] * 3])[order]   # depth 1 is nearer
        rgb = np.array([[0, 0, 255], [0, 255, 0]], np.uint8)[order]
        img = raster_triangles(tri, depth, rgb, 80, 80)
        assert tuple(img[20, 20]) == (0, 255, 0)
        assert tuple(img[70, 70]) == (255, 255, 255)


def test_top_view_shows_the_highest_point_of_each_pixel():
    s = 1e-3
    g = np.arange(10) * s + 0.5 * s
    X, Y = np.meshgrid(g, g)
    low = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    high = low + [0, 0, 1e-3]
    pts = np.concatenate([high, low])              # the high points first: order must not matter
    cols = np.concatenate([np.tile([[200, 0, 0]], (100, 1)), np.tile([[0, 0, 200]], (100, 1))]).astype(np.uint8)
    panel = top_view(pts, cols, s)
    assert panel.rgb.shape == (10, 10, 3)          # no row or column lost to round-off
    assert (panel.rgb == [200, 0, 0]).all()
    x0, x1, y0, y1 = panel.extent_mm
    assert (x0, x1, y0, y1) == pytest.approx((0.0, 10.0, 0.0, 10.0))


def test_ticks_are_round_and_inside():
    t = nice_ticks(0.0, 459.0)
    assert list(t) == [0, 100, 200, 300, 400]
    t = nice_ticks(-0.013, 0.027)
    assert t[0] >= -0.013 and t[-1] <= 0.027 and np.allclose(np.diff(t), 0.01)


def test_colour_table_lookup_matches_the_colormap():
    import matplotlib

    from simulate.machining.virtual_workpiece import STOCK_GREY, _colours

    rng = np.random.default_rng(0)
    v = np.r_[rng.normal(size=20000), 0.0, 1.0, np.nan, -5.0, 5.0]
    cols, lo, hi = _colours(v)
    ok = np.isfinite(v)
    norm = np.clip(np.where(ok, (np.nan_to_num(v) - lo) / (hi - lo), 0.0), 0.0, 1.0)
    ref = np.round(matplotlib.colormaps["viridis"](norm) * 255).astype(np.uint8)
    ref[~ok] = STOCK_GREY
    np.testing.assert_array_equal(cols, ref)


def test_saved_workpiece_reads_back(tmp_path):
    from simulate.machining.dexel import TriDexel
    from simulate.machining.simulation import StepTable
    from simulate.machining.virtual_workpiece import VirtualWorkpiece

    wp = TriDexel.box([0, 0, 0], [0.01, 0.01, 0.005], 1e-3)
    n = 4
    st = StepTable(*(np.zeros((n, 3)) if k in ("deflection", "tracking_error") else np.arange(n)
                     for k in StepTable.__dataclass_fields__))
    back = VirtualWorkpiece.load(VirtualWorkpiece(wp, st).save(tmp_path / "w.npz"))
    for a, b in zip(wp.families, back.workpiece.families, strict=False):
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_array_equal(back.steps.t, st.t)


def test_viridis_lookup_is_matplotlibs_colormap_call():
    import matplotlib

    from simulate.machining.raster_figure import viridis

    x = np.r_[np.linspace(0, 1, 1001), 0.99999999, 1.0]
    np.testing.assert_array_equal(viridis(x), np.round(matplotlib.colormaps["viridis"](x) * 255).astype(np.uint8))
