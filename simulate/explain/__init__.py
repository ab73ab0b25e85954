"""Explain a measured part: simulate it again, compare point by point and feature by feature,
name the cause (``stiffness:<axis>``, ``backlash:<axis>``, ``friction:<axis>``, ``tool_radius``,
``thermal`` or ``none``), calibrate it by re-simulating and report the gain.

Modules: :mod:`~simulate.explain.simulation` (setup, re-simulation with a robot file),
:mod:`~simulate.explain.measured` (scan / feature table reading), :mod:`~simulate.explain.comparison`
(probing the simulation at the measured points), :mod:`~simulate.explain.signatures` (size, ovality,
lobing, trends, reversal steps and spikes), :mod:`~simulate.explain.causes` (sensitivities, choice),
:mod:`~simulate.explain.calibration`, :mod:`~simulate.explain.pipeline` (:func:`explain_part`),
:mod:`~simulate.explain.report`.
"""
from simulate.explain.pipeline import Explanation, explain_part
from simulate.explain.simulation import PartSetup, load_setup, simulate_part

__all__ = ["Explanation", "explain_part", "PartSetup", "load_setup", "simulate_part"]
