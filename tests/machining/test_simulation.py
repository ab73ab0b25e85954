"""Coupled loop: ideal walls at nominal from dexel ends; deflection error scales with compliance."""
import numpy as np
import pytest

from simulate.machining.cutting import Spindle, load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.simulation import simulate_machining
from simulate.machining.tools import make_cutter
from simulate.machining.virtual_workpiece import VirtualWorkpiece

R = 5e-3
Y0 = 0.0203      # block edge [m]
AE = 0.5e-3      # radial depth: the cutter's -y side finishes the wall at Y0 - AE


def _wall_cut(compliance_scale):
    wp = TriDexel.box([0, 0, 0], [0.05, Y0, 0.01], 0.25e-3)
    feed = 0.05  # m/s
    x = np.arange(-0.008, 0.058, feed * 0.002)
    n = len(x)
    xyz = np.column_stack([x, np.full(n, Y0 + R - AE), np.full(n, 0.006)])
    C = None if compliance_scale == 0 else np.broadcast_to(np.eye(3) * 1e-7 * compliance_scale, (n, 3, 3))
    res = simulate_machining(wp, make_cutter("flat", 2 * R), np.arange(n) * 0.002, np.zeros(n, int), xyz,
                             load_material("Al7075"), Spindle.from_rpm(12000), compliance=C)
    # the machined wall: y-ray ends at heights inside the cut, x in the middle
    vw = VirtualWorkpiece(wp, res.steps)
    pts, sign, attrs = vw.end_attributes(1)
    sel = (attrs["step"] >= 0) & (sign > 0) & (pts[:, 0] > 0.015) & (pts[:, 0] < 0.035) & (pts[:, 2] > 0.0065)
    return pts[sel, 1], res, vw


def test_ideal_wall_at_nominal_within_2um():
    y, res, _ = _wall_cut(0)
    assert len(y) > 100
    assert np.all(np.abs(y - (Y0 - AE)) < 2e-6)


def test_wall_error_scales_with_compliance():
    y0, _, _ = _wall_cut(0)
    y1, r1, _ = _wall_cut(1)
    y2, r2, _ = _wall_cut(2)
    e1 = np.mean(y1) - np.mean(y0)
    e2 = np.mean(y2) - np.mean(y0)
    assert abs(e1) > 1e-6
    assert e2 / e1 == pytest.approx(2.0, rel=0.1)
    assert np.all(np.isfinite(r2.steps.force))


def test_save_load_probe(tmp_path):
    y, res, vw = _wall_cut(1)
    p = vw.save(tmp_path / "vw.npz")
    vw2 = VirtualWorkpiece.load(p)
    np.testing.assert_array_equal(vw2.workpiece.families[1].hi, vw.workpiece.families[1].hi)
    # probe from outside towards -y onto the machined wall (hits the exact dexel end)
    hit = vw2.probe([[0.025, 0.03, 0.008]], [[0, -1, 0]])
    assert np.isfinite(hit).all()
    assert abs(hit[0, 1] - np.median(y)) < 20e-6


def test_parallel_steps_match_serial():
    """Steps run in parallel over layers/rows (forced by parallel_work=1) give the serial result."""
    out = []
    for work in (200_000, 1):
        wp = TriDexel.box([0, 0, 0], [0.03, 0.02, 0.01], 0.5e-3)
        n = 40
        x = np.linspace(-0.006, 0.036, n)
        xyz = np.column_stack([x, np.full(n, 0.0101), np.linspace(0.009, 0.006, n)])
        C = np.broadcast_to(np.eye(3) * 2e-7, (n, 3, 3))
        res = simulate_machining(wp, make_cutter("bull", 8e-3), np.arange(n) * 0.002, np.arange(n), xyz,
                                 load_material("Al7075"), Spindle.from_rpm(12000), compliance=C, parallel_work=work)
        out.append((wp, res))
    (w0, r0), (w1, r1) = out
    for f0, f1 in zip(w0.families, w1.families, strict=False):
        np.testing.assert_array_equal(f0.count, f1.count)
        np.testing.assert_array_equal(f0.lo, f1.lo)
        np.testing.assert_array_equal(f0.hi_step, f1.hi_step)
    np.testing.assert_allclose(r1.steps.force, r0.steps.force, rtol=1e-12, atol=1e-9)
    assert r1.removed_volume == pytest.approx(r0.removed_volume, rel=1e-12)
    assert np.abs(r0.steps.force).max() > 10
