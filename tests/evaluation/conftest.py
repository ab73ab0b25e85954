"""Fixtures for the evaluation tests: the nominal test piece as dexels (exact ray ends)."""
from __future__ import annotations

import pytest

from simulate.evaluation.nominal import nominal_workpiece
from simulate.toolpath.testpiece import iso_test_piece


@pytest.fixture(scope="session")
def piece160():
    return iso_test_piece(160)


def grid_for(piece, spacing):
    h = piece.block / 2 + 0.001
    return [-h, -h, -0.002], [h, h, piece.top + 0.004], spacing


@pytest.fixture(scope="session")
def grid():
    """grid(piece, spacing) -> (lower, upper, spacing) covering the piece above z = -2 mm."""
    return grid_for


@pytest.fixture(scope="session")
def nominal160(piece160):
    lower, upper, s = grid_for(piece160, 0.002)
    return nominal_workpiece(piece160, lower, upper, s)
