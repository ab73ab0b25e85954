"""The gear's torque-twist law against the catalogue's hysteresis curve and its definitions.

RV reducer catalogues (Nabtesco) quote, from the torque-twist hysteresis curve measured with the
input locked: the lost motion (the twist between the midpoints of the curve's width at +-3 % of the
rated torque), the hysteresis loss (the curve's twist width at zero torque) and the torsional
rigidity (the curve's slope at high torque). Here the curve is traced from the law by a
quasi-static torque cycle (the twist found for each torque by bisection on the law, both
branches) and the three quantities are read from it the way the catalogue defines them.
"""
from __future__ import annotations

import numpy as np
import pytest

from simulate.robot.drive import (
    drive_params,
    elastic_torque,
    elastic_twist,
    elastic_twist_array,
    gear_torque,
    gear_torque_soft,
    local_stiffness,
)

RATED = 1568.0            # Nm
C = 1.2e6                 # Nm/rad, torsional rigidity
B = 1.2e-4                # rad, play (hysteresis loss)
LOST = 2.9e-4             # rad, lost motion (1 arcmin)
T_LM = 0.03 * RATED       # Nm, the torque the lost motion is quoted at


P1 = 0.5 * (LOST - B)     # rad, the soft zone beyond the play (the lost motion includes the play)


def _twist(tau):
    """Twist at the static torque ``tau`` on the law's curve, by bisection on the law (no inverse
    used); at ``tau = 0`` the play leaves it anywhere within +-b/2."""
    lo, hi = -0.02, 0.02
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if gear_torque_soft(C, 0.0, 0.5 * B, T_LM, P1, mid, 0.0) < tau:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_catalogue_quantities_read_from_the_traced_curve():
    # hysteresis loss: the twist width at zero torque (approached from both sides)
    eps = 1e-6
    assert _twist(eps) - _twist(-eps) == pytest.approx(B, rel=1e-3)
    # lost motion: the twist between -3 % and +3 % of the rated torque
    assert _twist(T_LM) - _twist(-T_LM) == pytest.approx(LOST, rel=1e-6)
    # torsional rigidity: the slope between half and full rated torque
    assert 0.5 * RATED / (_twist(RATED) - _twist(0.5 * RATED)) == pytest.approx(C, rel=1e-6)
    # the soft zone: softer below the lost-motion torque than the rigidity
    k_soft = T_LM / P1
    assert 0.6 * T_LM / (_twist(0.8 * T_LM) - _twist(0.2 * T_LM)) == pytest.approx(k_soft, rel=1e-6)
    assert k_soft < C


def test_robot_file_lost_motion_gives_the_soft_zone(robot):
    LM6 = np.array([2.9e-4, 2.9e-4, 2.9e-4, 0.0, 0.0, 0.0])   # rad, 1 arcmin on A1-A3, none on the wrist
    dr = robot.drive
    tlm = np.where(LM6 > 0, 0.03 * dr.rated_torque, 0.0)
    r = robot.with_changes(drive=type(dr)(dr.damping, dr.rated_torque, dr.friction_side, lost_motion=LM6,
                                          lost_motion_torque=tlm))
    p = drive_params(r)
    np.testing.assert_allclose(p.p1, np.where(LM6 > 0, 0.5 * (LM6 - np.asarray(robot.backlash)), 0.0))
    np.testing.assert_allclose(p.t1, np.where(LM6 > 0, 0.03 * np.asarray(dr.rated_torque), 0.0))
    from identify.errors import InputError

    with pytest.raises(InputError, match="lost_motion"):
        robot.with_changes(drive=type(dr)(dr.damping, dr.rated_torque, dr.friction_side,
                                          lost_motion=np.full(6, 0.5e-4), lost_motion_torque=np.full(6, 10.0)))


def test_inverse_and_slope_of_the_spring():
    p1 = P1
    for tau in (-2000.0, -T_LM, -10.0, 0.0, 3.0, T_LM, 47.5, 900.0):
        x = elastic_twist(C, T_LM, p1, tau)
        assert elastic_torque(C, T_LM, p1, x) == pytest.approx(tau, abs=1e-9)
    assert local_stiffness(C, T_LM, p1, 10.0) == pytest.approx(T_LM / p1)
    assert local_stiffness(C, T_LM, p1, -100.0) == C
    # without a soft zone: the linear spring of the elasto-backlash element
    assert elastic_twist(C, 0.0, 0.0, 600.0) == pytest.approx(600.0 / C)
    assert elastic_torque(C, 0.0, 0.0, -1e-4) == pytest.approx(-C * 1e-4)
    assert gear_torque(C, 10.0, 0.5 * B, 2e-4, 0.01) == pytest.approx(C * (2e-4 - 0.5 * B) + 0.1)
    assert gear_torque_soft(C, 0.0, 0.5 * B, T_LM, p1, 0.5 * B + 0.5 * p1, 0.0) == pytest.approx(0.5 * T_LM)


def test_array_inverse_matches_the_kernel(robot):
    p = drive_params(robot)
    rng = np.random.default_rng(0)
    tau = rng.normal(0.0, 200.0, (50, 6))
    got = elastic_twist_array(p, tau)
    for k in range(50):
        for j in range(6):
            assert got[k, j] == pytest.approx(elastic_twist(p.c[j], p.t1[j], p.p1[j], tau[k, j]), rel=1e-12, abs=0)
