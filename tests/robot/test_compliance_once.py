"""Each compliance counted once: the drives wind the gears up under the process force, the static term
holds only the links'; the tool offset under a known force equals ``J K_total^-1 J^T F``.

Oracle: the Jacobian from Pinocchio (tests/robot/conftest.py builds the twin from the DH data), the
compliance written out here from the robot file's stiffnesses, not from the production code.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from simulate.machining.cutting import Spindle, load_material
from simulate.machining.dexel import TriDexel
from simulate.machining.simulation import loop_drive, simulate_machining, workpiece_compliance
from simulate.robot.drive import drive_flags
from simulate.robot.friction import loop_friction
from simulate.robot.kinematics import fk
from simulate.robot.stiffness import Compliance

from .conftest import linear_gear

Q_HELD = np.array([0.3, 0.55, -0.25, 0.4, 0.9, -0.2])   # rad, a reachable pose away from singularities
FORCE = np.array([150.0, -90.0, 120.0])                # N on the tool, base (= workpiece) frame


@pytest.fixture(scope="module")
def robot(robot):
    """The shipped robot with a linear gear beyond the play (no catalogue soft zone): the closed form
    ``J K^-1 J^T F`` is the linear one."""
    return linear_gear(robot)


def _pin_jacobian(make_pin_model, robot, q):
    import pinocchio as pin

    model = make_pin_model(robot)
    data = model.createData()
    fid = model.getFrameId("tcp")
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    return pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]


def _held(robot, part, *, drives=True, n=700, force=FORCE):
    """The coupled loop at a held pose with a constant force from step 1 on, friction and play off."""
    from simulate.evaluation.cutter import robot_cutter

    t = np.arange(n) * 0.002
    q = np.tile(Q_HELD, (n, 1))
    xyz = np.tile(fk(robot, Q_HELD)[:3, 3], (n, 1))
    eye = np.eye(3)
    drive = None
    if drives:
        flags = drive_flags(friction=False, backlash=False)
        fp = loop_friction(robot, {}, enabled=False)[0]
        drive = loop_drive(robot, q, t, eye, fp, flags=flags)
    C = workpiece_compliance(robot, q, eye, part=part)
    lo = xyz[0] - np.array([0.0, 0.0, 1.0])
    wp = TriDexel.box(lo, lo + 2e-3, 1e-3)   # material nowhere near the tool: the given force only
    fext = np.zeros((n, 3))
    fext[1:] = force
    return simulate_machining(wp, robot_cutter(robot), t, np.zeros(n, int), xyz, load_material("Al7075"),
                              Spindle.from_rpm(12000.0), compliance=C, forces=False, drive=drive,
                              external_force=fext)


def _expected(make_pin_model, robot, kinv, force=FORCE):
    J = _pin_jacobian(make_pin_model, robot, Q_HELD)
    return J @ np.diag(kinv) @ J.T @ force


@pytest.fixture(scope="module")
def soft_links(robot):
    """The shipped robot with link compliance as large as the gears' (so both paths carry half)."""
    return robot.with_changes(link_stiffness=np.array(robot.stiffness) * 1.0)


def test_held_force_gears_in_the_drives_only(robot, make_pin_model):
    # the shipped robot: rigid links, the gears' windup comes from the drives alone
    res = _held(robot, Compliance.LINK)
    want = _expected(make_pin_model, robot, 1.0 / robot.stiffness)
    got = res.steps.tool_offset()[-1]
    assert np.linalg.norm(want) > 50e-6
    assert np.linalg.norm(got - want) < 0.02 * np.linalg.norm(want)


def test_held_force_gears_and_links_each_once(soft_links, make_pin_model):
    r = soft_links
    res = _held(r, Compliance.LINK)
    want = _expected(make_pin_model, r, 1.0 / r.stiffness + 1.0 / r.link_stiffness)
    got = res.steps.tool_offset()[-1]
    assert np.linalg.norm(got - want) < 0.02 * np.linalg.norm(want)
    # the report's split: the deflection column holds the whole force-induced offset (gears' windup
    # and links), the tracking error the servo's rest (near zero at a held pose)
    d = res.steps.deflection[-2]
    assert np.linalg.norm(d - want) < 0.02 * np.linalg.norm(want)
    assert np.linalg.norm(res.steps.tracking_error[-1]) < 0.02 * np.linalg.norm(want)


def test_counting_the_gears_twice_is_caught(soft_links, make_pin_model):
    # the former composition (drives plus the total static compliance) doubles the gears' share
    r = soft_links
    res = _held(r, Compliance.TOTAL)
    want = _expected(make_pin_model, r, 1.0 / r.stiffness + 1.0 / r.link_stiffness)
    got = res.steps.tool_offset()[-1]
    assert np.linalg.norm(got - want) > 0.3 * np.linalg.norm(want)


def test_without_drives_the_static_term_holds_both(soft_links, make_pin_model):
    r = soft_links
    res = _held(r, Compliance.TOTAL, drives=False)
    want = _expected(make_pin_model, r, 1.0 / r.stiffness + 1.0 / r.link_stiffness)
    got = res.steps.tool_offset()[-1]
    assert np.linalg.norm(got - want) < 0.02 * np.linalg.norm(want)


def test_stiffness_scale_scales_the_gears_in_the_drives(robot, make_pin_model):
    t = np.arange(600) * 0.002
    q = np.tile(Q_HELD, (600, 1))
    fp = loop_friction(robot, {}, enabled=False)[0]
    p1 = loop_drive(robot, q, t, np.eye(3), fp, stiffness_scale=1.0).params
    p2 = loop_drive(robot, q, t, np.eye(3), fp, stiffness_scale=1.25).params
    np.testing.assert_allclose(p2.c, 1.25 * p1.c)
    np.testing.assert_allclose(p2.t1, 1.25 * p1.t1)


# ---------------------------------------------------------------- along a cut, through the pipeline

SIDE_CUT = """%
(side cut at constant radial engagement: 2 mm of the 10 mm cutter, 4 mm deep, along x)
G21 G90 G17 G94
S12000 M3
G0 X-10 Y-3 Z5
G0 X-10 Y-3 Z-4
G1 X70 Y-3 Z-4 F1500
G0 X70 Y-3 Z5
M30
%
"""


@pytest.fixture(scope="module")
def side_cut(tmp_path_factory):
    d = tmp_path_factory.mktemp("sidecut")
    (d / "side.nc").write_text(SIDE_CUT)
    (d / "side.stock.json").write_text(json.dumps(
        {"units": "mm", "base": {"name": "block", "kind": "polygon",
                                 "vertices": [[0, 0], [60, 0], [60, 30], [0, 30]], "z_bottom": -10,
                                 "top": {"z0": 0}}, "blanks": []}))
    return d / "side.nc"


def test_steady_cut_offset_is_the_total_compliance_once(robot, side_cut, make_pin_model):
    from simulate.pipeline import Components, MachiningJob, MachiningSettings, run_job
    from simulate.robot.kinematics import jacobian
    from simulate.toolpath.placement import Placement

    pl = Placement("near", np.array([1.45, -0.03, -0.1]), np.zeros(3))
    job = MachiningJob(program=side_cut, robot=robot, placement=pl,
                       components=Components(friction=False, switching=False),
                       settings=MachiningSettings(spacing=0.5e-3, size=0))
    mo = run_job(job)
    st = mo.steps
    F = st.force
    steady = np.flatnonzero((np.linalg.norm(F, axis=1) > 20.0) & (st.t > st.t[0]))
    x = mo.trajectory.xyz[:, 0]
    steady = steady[(x[steady] > 0.015) & (x[steady] < 0.045)]   # away from the entry and the exit
    assert steady.size > 200
    # the oracle: J K^-1 J^T F at each step (Jacobian here from the kinematics, checked against
    # Pinocchio at one step), the force of the step before (the loop's one-step lag), mean over the cut
    J = jacobian(robot, mo.trajectory.q[steady - 1])[:, :3]
    np.testing.assert_allclose(J[0], _pin_jacobian(make_pin_model, robot, mo.trajectory.q[steady[0] - 1]),
                               atol=1e-9)
    kinv = 1.0 / robot.stiffness
    want = np.einsum("nij,j,nkj,nk->ni", J, kinv, J, F[steady - 1])
    got = st.tool_offset()[steady]
    w, g = want.mean(axis=0), got.mean(axis=0)
    assert np.linalg.norm(w) > 20e-6
    assert np.linalg.norm(g - w) < 0.05 * np.linalg.norm(w)


def test_attribution_keeps_the_tool_offset_and_moves_the_lagged_windup():
    """The report's split on random forces: the tool offset is unchanged to round-off, and the
    deflection grows by the lagged quasi-static windup ``J K^-1 J^T F`` (written out plainly here)."""
    from types import SimpleNamespace

    from simulate.machining.simulation import StepTable, attribute_gear_windup

    rng = np.random.default_rng(3)
    n = 400
    st = StepTable.zeros(n)
    st.t[:] = np.arange(n) * 0.002
    st.force[:] = rng.normal(0.0, 100.0, (n, 3))
    st.deflection[:] = rng.normal(0.0, 1e-5, (n, 3))
    st.tracking_error[:] = rng.normal(0.0, 1e-5, (n, 3))
    jac = rng.normal(0.0, 1.0, (n, 3, 6))
    c = np.array([1e6, 2e6, 1.5e6, 3e5, 2e5, 1e5])
    z = np.zeros(6)
    drive = SimpleNamespace(params=SimpleNamespace(c=c, t1=z, p1=z), jac=jac, model=rng.normal(0, 50, (n, 6)))
    before = st.tool_offset().copy()
    d0 = st.deflection.copy()
    tau = 0.005
    attribute_gear_windup(st, drive, tau)
    np.testing.assert_allclose(st.tool_offset(), before, rtol=0, atol=1e-15)
    a = 1.0 - np.exp(-0.002 / tau)
    g = np.zeros(3)
    for k in range(1, n):
        target = jac[k] @ (jac[k].T @ st.force[k] / c)
        g = g + a * (target - g)
        np.testing.assert_allclose(st.deflection[k] - d0[k], g, rtol=1e-9, atol=1e-18)


def _catalogue_twist(c, t1, p1, tau):
    """Twist [rad] of the catalogue curve's midline (no play) at torque tau [Nm]: slope t1 / p1 up to
    the lost-motion torque t1, then the rigidity c (written out here, not the production law)."""
    a = np.abs(tau)
    return np.sign(tau) * np.where(a <= t1, a * p1 / t1, p1 + (a - t1) / c)


def test_held_force_with_the_catalogue_soft_zone(make_pin_model):
    """The shipped robot with its soft zone: the held tool moves by J [twist(-g + J^T F) - twist(-g)],
    twist the catalogue curve, -g each gear's static torque in the drives' sign (g Pinocchio's RNEA
    gravity torque), with and without the force.
    A joint whose load stays inside +-3 % of its rated torque moves on the soft slope."""
    import pinocchio as pin

    from simulate.robot.model import load_robot

    from .conftest import MAX100

    shipped = load_robot(MAX100)
    res = _held(shipped, Compliance.LINK)
    model = make_pin_model(shipped)
    data = model.createData()
    g = pin.rnea(model, data, Q_HELD, np.zeros(6), np.zeros(6))
    J = _pin_jacobian(make_pin_model, shipped, Q_HELD)
    lm, t1, b = shipped.drive.lost_motion, shipped.drive.lost_motion_torque, shipped.backlash
    p1 = (lm - b) / 2
    tw = [_catalogue_twist(shipped.stiffness, t1, p1, tau) for tau in (-g, -g + J.T @ FORCE)]
    want = J @ (tw[1] - tw[0])
    linear = J @ ((J.T @ FORCE) / shipped.stiffness)
    got = res.steps.tool_offset()[-1]
    assert np.linalg.norm(want - linear) > 0.1 * np.linalg.norm(linear)   # the soft zone matters here
    assert np.linalg.norm(got - want) < 0.02 * np.linalg.norm(want)
