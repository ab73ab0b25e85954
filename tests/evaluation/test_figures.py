"""Report figures are written atomically: a PNG whole, or the file as it was."""
from __future__ import annotations

import pytest

from simulate.figures import pyplot, save_png


def _figure():
    fig, ax = pyplot().subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    return fig


def test_save_png_writes_a_png_and_closes_the_figure(tmp_path):
    fig = _figure()
    assert save_png(fig, tmp_path / "line.png", dpi=50) == "line.png"
    assert (tmp_path / "line.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["line.png"]
    assert not pyplot().fignum_exists(fig.number)


def test_a_failing_figure_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "line.png"
    target.write_bytes(b"old")
    fig = _figure()

    def fail(*args, **kwargs):
        raise RuntimeError("renderer failed")

    monkeypatch.setattr(fig, "savefig", fail)
    with pytest.raises(RuntimeError, match="renderer failed"):
        save_png(fig, target)
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["line.png"]
    assert not pyplot().fignum_exists(fig.number)
