"""The path guard against a real tree with symbolic links pointing in and out, and `..` in every
position: a path is accepted exactly when its fully resolved target lies inside the base (checked here
with os.path.realpath and a string prefix, not the guard's own Path logic)."""
from __future__ import annotations

import os

import pytest

from service.paths import NotFound, inside


@pytest.fixture()
def tree(tmp_path):
    base = tmp_path / "base"
    (base / "sub").mkdir(parents=True)
    (base / "sub" / "f.txt").write_text("in")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.txt").write_text("out")
    (tmp_path / "base-twin").mkdir()                       # shares the base's name as a prefix
    (base / "link_in").symlink_to(base / "sub")            # stays inside
    (base / "link_out").symlink_to(outside)                # leaves
    (base / "sub" / "up").symlink_to(tmp_path)             # leaves through a parent
    (base / "file_out").symlink_to(outside / "secret.txt")
    return base


CASES = [("sub", "f.txt"), ("link_in", "f.txt"), ("link_out", "secret.txt"), ("file_out",),
         ("sub", "up", "outside", "secret.txt"), ("sub", "up", "base", "sub", "f.txt"), ("..", "outside"),
         ("sub", "..", "sub", "f.txt"), ("sub", "..", "..", "base-twin"), ("..", "base-twin"),
         ("link_in", "..", "sub"), (".",), ("sub", "up", "base")]


@pytest.mark.parametrize("parts", CASES)
def test_accepted_exactly_when_the_resolved_target_is_inside(tree, parts):
    real_base = os.path.realpath(tree)
    target = os.path.realpath(os.path.join(tree, *parts))
    expected_inside = target == real_base or target.startswith(real_base + os.sep)
    if expected_inside:
        assert str(inside(tree, *parts)) == target
    else:
        with pytest.raises(NotFound):
            inside(tree, *parts)
