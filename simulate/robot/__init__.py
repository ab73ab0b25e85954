"""The robot model (paper 2.1, 3.2, 3.5, 3.6): robot files, kinematics, dynamics, stiffness, drives.

Modules: :mod:`~simulate.robot.model` (load/save robot files), :mod:`~simulate.robot.kinematics`
(FK, Jacobian, analytic IK), :mod:`~simulate.robot.dynamics` (RNEA), :mod:`~simulate.robot.stiffness`
(Cartesian compliance, deflection), :mod:`~simulate.robot.drive` (two-mass drives, cascaded control),
:mod:`~simulate.robot.friction` (friction tables), :mod:`~simulate.robot.prepare` (six-axis log ->
axis records), :mod:`~simulate.robot.tables` (pose/joint tables).
"""
from simulate.robot.model import Robot, Tool, load_robot, save_robot

__all__ = ["Robot", "Tool", "load_robot", "save_robot"]
