"""Ray capacity in the coupled loop: a family whose ray fills up is grown between steps, with the same
result as a workpiece that had room from the start (oracle: the same cuts on a large capacity)."""
from __future__ import annotations

import numpy as np

from simulate.machining.cutting import Spindle, load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.simulation import CAPACITY_STEP, simulate_machining
from simulate.machining.tools import make_cutter


def _slots(helpers, across_x: bool):
    """Six 3 mm deep slots 3 mm apart through a 20 x 20 x 10 mm block [m]: across the x-rays (each
    x-ray under the slots ends with seven intervals) or across the y-rays."""
    pts = []
    for c in np.arange(6) * 3e-3 + 2.5e-3:
        a, b = ((c, -3e-3, 7e-3), (c, 23e-3, 7e-3)) if across_x else ((-3e-3, c, 7e-3), (23e-3, c, 7e-3))
        pts.append(helpers.line(np.add(a, (0, 0, 5e-3)), a, 0.5e-3))
        pts.append(helpers.line(a, b, 0.5e-3))
        pts.append(helpers.line(b, np.add(b, (0, 0, 5e-3)), 0.5e-3))
    return np.vstack(pts)


def _run(capacity, pts):
    wp = TriDexel.box([0, 0, 0], [20e-3, 20e-3, 10e-3], 0.5e-3, capacity=capacity)
    n = len(pts)
    res = simulate_machining(wp, make_cutter("flat", 2e-3, flutes=2), np.arange(n) * 0.002, np.zeros(n, int), pts,
                             load_material("Al7075"), Spindle.from_rpm(12000), forces=False)
    return wp, res


def _rays(fam):
    return [(fam.lo[r, :c].tolist(), fam.hi[r, :c].tolist(), fam.lo_step[r, :c].tolist(), fam.hi_step[r, :c].tolist())
            for r, c in enumerate(fam.count)]


def test_full_ray_family_is_grown_and_gives_the_same_part(helpers):
    for across_x, grown in ((True, 0), (False, 1)):
        pts = _slots(helpers, across_x)
        small, rs = _run((1, 1, 1), pts)
        big, rb = _run((16, 16, 16), pts)
        # only the family whose rays the slots split needed more room than the first free slots
        assert small.families[grown].capacity > 1 + CAPACITY_STEP
        assert small.families[1 - grown].capacity == 1 + CAPACITY_STEP
        assert int(small.families[grown].count.max()) == 7
        for fs, fb in zip(small.families, big.families, strict=True):
            assert _rays(fs) == _rays(fb)
        assert rs.removed_volume == rb.removed_volume > 0
