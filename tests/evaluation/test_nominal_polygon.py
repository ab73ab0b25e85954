"""The nominal part's polygon test: a closed convex polygon (its edges and corners inside, as the
x/y-ray chords of the same prism include their end points), against scipy's Delaunay point location."""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, Delaunay

from simulate.evaluation.nominal import _inside_polygon

SQUARE = np.array([[0.0, 0.0], [0.25, 0.0], [0.25, 0.25], [0.0, 0.25]])  # counter-clockwise, exact in binary


def test_edges_and_corners_of_a_square_are_inside():
    x = np.array([0.125, 0.25, 0.125, 0.0, 0.0, 0.25, 0.125, 0.125, -1e-12, 0.25 + 1e-12])
    y = np.array([0.0, 0.0625, 0.25, 0.125, 0.0, 0.25, 0.125, -1e-12, 0.125, 0.125])
    want = np.array([True, True, True, True, True, True, True, False, False, False])
    np.testing.assert_array_equal(_inside_polygon(SQUARE, x, y), want)


def test_random_convex_polygons_against_delaunay():
    rng = np.random.default_rng(11)
    for _ in range(200):
        pts = rng.uniform(-1.0, 1.0, size=(12, 2))
        hull = ConvexHull(pts)
        verts = pts[hull.vertices]                 # counter-clockwise in 2-D
        xy = rng.uniform(-1.2, 1.2, size=(400, 2))
        tri = Delaunay(verts)
        want = tri.find_simplex(xy) >= 0
        # leave out points within 1e-9 of an edge, where the two tolerances may differ
        eq = hull.equations                        # n . x + d <= 0 inside
        margin = np.abs(xy @ eq[:, :2].T + eq[:, 2]).min(axis=1)
        far = margin > 1e-9
        got = _inside_polygon(verts, xy[:, 0], xy[:, 1])
        np.testing.assert_array_equal(got[far], want[far])
