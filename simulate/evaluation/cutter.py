"""The cutter of a robot file: its ``[tool]`` table as a machining cutter (paper 3.3, 3.4).

The robot file is the one place that describes the tool on the spindle (type, diameter, corner
radius, flutes, helix, flute length): the tool radius is a calibratable parameter of that file
(``greybench explain``), so every simulation of the robot takes its cutter from there, never from a
stock or program description (those only say which tool number the program expects).
"""
from __future__ import annotations

import math

from simulate.robot.model import Robot


def robot_cutter(robot: Robot):
    """The robot file's ``[tool]`` as a :class:`simulate.machining.tools.Cutter`.

    Parameters
    ----------
    robot : simulate.robot.model.Robot
        ``robot.tool``: diameter [m], corner_radius [m] (ignored for a flat end mill), flutes [-],
        helix [rad], length [m] (flute length).

    Returns
    -------
    simulate.machining.tools.Cutter
        In the tool frame (origin at the tool tip = TCP, +z towards the spindle), SI units.
    """
    from simulate.machining.tools import make_cutter

    t = robot.tool
    return make_cutter(t.type, float(t.diameter), corner_radius=float(t.corner_radius) if t.type != "flat" else None,
                       flutes=int(t.flutes), helix_deg=math.degrees(float(t.helix)), length=float(t.length))
