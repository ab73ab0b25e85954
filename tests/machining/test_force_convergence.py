"""Cutting force of short programs against the closed-form mechanistic force and against a finer grid.

The cuts are those of the ISO 10791-7 finishing programs (flat end mill D10, 3 teeth, 30 deg
helix, 12000 rev/min, 2000 mm/min, Al7075): a full slot, a side cut at constant radial engagement
along x and along a 30 deg line, and a deep wall. The reference is written out here, independently
of the production kernels (Altintas, Manufacturing Automation, 2nd ed., ch. 2; docs/cutting-forces.md):

- edge force per unit length ``f_i = Kic h + Kie`` (i = t, r, a), ``h = c sin(phi)``, ``c`` the feed
  per tooth, ``phi`` the immersion angle from the feed normal on the side the teeth enter;
- revolution-mean forces: the same integrated over the engagement ``[phi_st, phi_ex]``, times
  ``N a / (2 pi)`` (closed form below); full slot: ``Fx = -N a Krc c/4 - N a Kre/pi``,
  ``Fy = N a Ktc c/4 + N a Kte/pi``, ``|Fz| = N a Kac c/pi + N a Kae/2``;
- instantaneous force (for the peak): each tooth's helical edge summed over 1 um slices of the
  axial depth, at 1440 tooth positions per revolution.

Acceptance (per steady step, both grids): the revolution-mean force within 10 % of the closed
form, its mean within 2 %; the largest mean and the largest instantaneous force at the 0.25 mm
ranking grid within 10 % of the 0.125 mm grid; the largest instantaneous force within 10 % of the
analytic peak. A force step where the edge crosses a grid line would break the per-step bound.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from simulate.machining import closed_form
from simulate.machining.cutting import load_material
from simulate.machining.dexel import ConvexSolid, TriDexel
from simulate.machining.tools import make_cutter

R, N, HELIX_DEG, RPM = 5e-3, 3, 30.0, 12000.0
FEED = 2000.0 / 60.0 * 1e-3            # m/s
C = FEED / (N * RPM / 60.0)            # feed per tooth [m] (0.0556 mm)
DT = 0.002                             # s, the interpolation cycle
RANKING, FINE = 0.25e-3, 0.125e-3      # dexel spacings [m]
LENGTH = 30e-3                         # cut length [m]
STEADY = (R + 3e-3, LENGTH - 3e-3)     # path coordinate window of steady cutting [m]


def mean_force_local(phi_st, phi_ex, a, mat):
    """Altintas' revolution-mean force [N] of this file's cutter and feed (feed along local x)."""
    return closed_form.mean_force_local(phi_st, phi_ex, a, C, N, mat.kc, mat.ke)


def peak_force_local(phi_st, phi_ex, a, mat, n_phase=1440, dz=1e-6):
    """Largest instantaneous |F| [N] over a revolution: N helical teeth, edge lag ``z tan(beta) / R``."""
    Ktc, Krc, Kac = mat.kc
    Kte, Kre, Kae = mat.ke
    z = (np.arange(int(round(a / dz))) + 0.5) * dz
    lag = z * math.tan(math.radians(HELIX_DEG)) / R
    best = 0.0
    for phase in np.linspace(0.0, 2 * math.pi / N, n_phase // N, endpoint=False):
        F = np.zeros(3)
        for j in range(N):
            phi = np.mod(phase + 2 * math.pi * j / N - lag, 2 * math.pi)
            on = (phi >= phi_st) & (phi <= phi_ex)
            p = phi[on]
            h = C * np.sin(p)
            ft, fr, fa = (Ktc * h + Kte) * dz, (Krc * h + Kre) * dz, (Kac * h + Kae) * dz
            F += [np.sum(-ft * np.cos(p) - fr * np.sin(p)), np.sum(ft * np.sin(p) - fr * np.cos(p)), np.sum(fa)]
        best = max(best, float(np.linalg.norm(F)))
    return best


def _halfspace(n, b):
    return [n[0], n[1], n[2], b]


def cut(helpers, angle_deg, ae, depth, spacing):
    """Cut ``LENGTH`` along a line at ``angle_deg`` from +x with the tool tip at z = 0 through stock
    ``0 <= z <= depth`` on the right of the feed (down milling, as the test-piece contours) whose
    wall lies ``R - ae`` from the tool axis; ``ae >= 2 R``: a full slot. Returns the per-step forces
    (n, 4) of the steady window and the feed direction (3,)."""
    th = math.radians(angle_deg)
    u = np.array([math.cos(th), math.sin(th), 0.0])
    right = np.array([math.sin(th), -math.cos(th), 0.0])
    origin = np.array([0.01, 0.01, 0.0])
    near = R - ae
    hs = [_halfspace(-right, -(right @ origin + near)), _halfspace(right, right @ origin + R + 8e-3),
          _halfspace(u, u @ origin + LENGTH + R + 2e-3), _halfspace(-u, -(u @ origin)),
          _halfspace([0, 0, 1], depth), _halfspace([0, 0, -1], 0.0)]
    corners = [origin + s * u + d * right for s in (0.0, LENGTH + R + 2e-3) for d in (near, R + 8e-3)]
    lo = np.min(corners, axis=0)
    hi = np.max(corners, axis=0)
    lo[2], hi[2] = 0.0, depth
    wp = TriDexel.from_solids([ConvexSolid(np.array(hs), lo, hi)], spacing)
    s = np.arange(-R - 1e-3, LENGTH + 1e-12, FEED * DT)
    pts = origin + s[:, None] * u
    cutter = make_cutter("flat", 2 * R, flutes=N, helix_deg=HELIX_DEG, length=0.05)
    F = helpers.run_path(wp, cutter, pts, dt=DT, rpm=RPM)
    sel = (s[1:] > STEADY[0]) & (s[1:] < STEADY[1])
    return F[sel], u


def to_world(F_local, u):
    """Local (along feed, left of feed, |z|) -> workpiece frame; the axial force pulls into the part (-z)."""
    left = np.array([-u[1], u[0], 0.0])
    return F_local[0] * u + F_local[1] * left + np.array([0.0, 0.0, -F_local[2]])


# (name, angle [deg], radial engagement [m], axial depth [m])
CUTS = [
    ("slot", 0.0, 2 * R, 2e-3),
    ("side along x", 0.0, 0.5e-3, 6e-3),
    ("side along 30 deg", 30.0, 0.5e-3, 6e-3),
    ("deep wall", 0.0, 0.5e-3, 15e-3),
]


def engagement(ae):
    """[phi_st, phi_ex] of down milling with material on the right of the feed (teeth leave at pi)."""
    return (0.0, math.pi) if ae >= 2 * R else (math.pi - math.acos(1 - ae / R), math.pi)


@pytest.fixture(scope="module")
def runs():
    return {}


def _run(helpers, runs, name, spacing):
    key = (name, spacing)
    if key not in runs:
        _, ang, ae, depth = next(c for c in CUTS if c[0] == name)
        runs[key] = cut(helpers, ang, ae, depth, spacing)
    return runs[key]


def test_closed_forms_agree_with_each_other():
    """The two references in this file: the full-slot means as printed, and the instantaneous force
    averaged over a revolution equals the closed-form mean (a check of the check)."""
    mat = load_material("Al7075")
    Ktc, Krc, Kac = mat.kc
    Kte, Kre, Kae = mat.ke
    a = 2e-3
    slot = [-N * a * Krc * C / 4 - N * a * Kre / math.pi, N * a * Ktc * C / 4 + N * a * Kte / math.pi,
            N * a * Kac * C / math.pi + N * a * Kae / 2]
    np.testing.assert_allclose(mean_force_local(0.0, math.pi, a, mat), slot, rtol=1e-12)
    # a zero-helix single slice: the mean over tooth positions of the instantaneous force
    phi_st, phi_ex = engagement(0.5e-3)
    p = np.linspace(0, 2 * math.pi, 200001)[:-1]
    on = (p >= phi_st) & (p <= phi_ex)
    h = C * np.sin(p[on])
    ft, fr, fa = Ktc * h + Kte, Krc * h + Kre, Kac * h + Kae
    mean = N * a * np.array([np.sum(-ft * np.cos(p[on]) - fr * np.sin(p[on])),
                             np.sum(ft * np.sin(p[on]) - fr * np.cos(p[on])), np.sum(fa)]) / len(p)
    np.testing.assert_allclose(mean, mean_force_local(phi_st, phi_ex, a, mat), rtol=2e-4)


@pytest.mark.parametrize("name", [c[0] for c in CUTS])
@pytest.mark.parametrize("spacing", [RANKING, FINE])
def test_every_step_within_ten_percent_of_the_closed_form(helpers, runs, name, spacing):
    _, _, ae, depth = next(c for c in CUTS if c[0] == name)
    F, u = _run(helpers, runs, name, spacing)
    ref = to_world(mean_force_local(*engagement(ae), depth, load_material("Al7075")), u)
    err = np.linalg.norm(F[:, :3] - ref, axis=1) / np.linalg.norm(ref)
    assert len(F) > 250
    assert err.max() < 0.10, f"worst step {err.max():.1%} off the closed form"
    np.testing.assert_allclose(F[:, :3].mean(axis=0), ref, atol=0.02 * np.linalg.norm(ref))


@pytest.mark.parametrize("name", [c[0] for c in CUTS])
def test_peaks_at_the_ranking_grid_within_ten_percent_of_the_fine_grid(helpers, runs, name):
    _, _, ae, depth = next(c for c in CUTS if c[0] == name)
    coarse, _ = _run(helpers, runs, name, RANKING)
    fine, _ = _run(helpers, runs, name, FINE)
    mean_c = np.linalg.norm(coarse[:, :3], axis=1).max()
    mean_f = np.linalg.norm(fine[:, :3], axis=1).max()
    assert mean_c == pytest.approx(mean_f, rel=0.10)
    assert coarse[:, 3].max() == pytest.approx(fine[:, 3].max(), rel=0.10)


#: Known gap: at 0.25 mm a wall parallel to a ray family gives a peak 10.3 % above the helical
#: reference (202 N against 183.5 N; 0.125 mm: +2.9 % / +6.2 %): the instantaneous force takes an
#: edge point as engaged when its nearest sample is, so the engaged arc reaches up to half a sample
#: pitch beyond the wall. Strict: the mark must go when that is fixed.
_PEAK_GAP = pytest.mark.xfail(strict=True, reason="nearest-sample engagement of the instantaneous force, 0.25 mm")


@pytest.mark.parametrize(("name", "spacing"), [
    ("slot", RANKING), ("slot", FINE),
    pytest.param("side along x", RANKING, marks=_PEAK_GAP), ("side along x", FINE),
    ("side along 30 deg", RANKING), ("side along 30 deg", FINE),
    pytest.param("deep wall", RANKING, marks=_PEAK_GAP), ("deep wall", FINE),
])
def test_peak_within_ten_percent_of_the_helical_edge_reference(helpers, runs, name, spacing):
    _, _, ae, depth = next(c for c in CUTS if c[0] == name)
    F, _ = _run(helpers, runs, name, spacing)
    peak = peak_force_local(*engagement(ae), depth, load_material("Al7075"))
    assert F[:, 3].max() == pytest.approx(peak, rel=0.10)
