"""The one atomic writer (identify.files) and the one markdown table writer (identify.records)."""
import os
import stat

import pytest

from identify.files import atomic_file, atomic_folder, write_text_atomic
from identify.records import markdown_table


def _leftovers(folder):
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_atomic_file_replaces_only_when_the_block_ends_well(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_file(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("failed while writing")
    assert target.read_text() == "old" and _leftovers(tmp_path) == []
    old = os.umask(0o022)
    try:
        write_text_atomic(target, "new")
    finally:
        os.umask(old)
    assert target.read_text() == "new" and _leftovers(tmp_path) == []
    assert stat.S_IMODE(target.stat().st_mode) == 0o644  # not the 0600 of the temporary


def test_atomic_folder_replaces_a_folder_or_leaves_it(tmp_path):
    target = tmp_path / "model"
    target.mkdir()
    (target / "a.txt").write_text("old")
    with pytest.raises(ValueError), atomic_folder(target) as stage:
        (stage / "b.txt").write_text("half")
        raise ValueError("failed while writing")
    assert sorted(p.name for p in target.iterdir()) == ["a.txt"] and _leftovers(tmp_path) == []
    with atomic_folder(target) as stage:
        (stage / "b.txt").write_text("new")
    assert sorted(p.name for p in target.iterdir()) == ["b.txt"] and _leftovers(tmp_path) == []


def test_atomic_file_mode_keeps_a_secret_private(tmp_path):
    target = tmp_path / "secret"
    old = os.umask(0o022)
    try:
        with atomic_file(target, mode=0o600) as tmp:
            tmp.write_text("abc")
    finally:
        os.umask(old)
    assert target.read_text() == "abc" and _leftovers(tmp_path) == []
    assert stat.S_IMODE(target.stat().st_mode) == 0o600  # not the umask's 0644


def test_atomic_folder_without_replace_keeps_the_first_writers_folder(tmp_path):
    target = tmp_path / "cache"
    with atomic_folder(target, replace=False) as stage:
        (stage / "a.txt").write_text("first")
    assert (target / "a.txt").read_text() == "first"
    # a second writer of the same key finishes later: the first folder stays, the second is dropped
    with atomic_folder(target, replace=False) as stage:
        (stage / "b.txt").write_text("second")
    assert sorted(p.name for p in target.iterdir()) == ["a.txt"] and _leftovers(tmp_path) == []
    with pytest.raises(ValueError), atomic_folder(tmp_path / "other", replace=False) as stage:
        raise ValueError("failed while writing")
    assert not (tmp_path / "other").exists() and _leftovers(tmp_path) == []


def test_markdown_table_lines():
    lines = markdown_table(("model", "RMSE [Nm]"), [("lugre", "0.0213"), ("a|b", 2)])
    assert lines == ["| model | RMSE [Nm] |", "|---|---|", "| lugre | 0.0213 |", "| a\\|b | 2 |"]
    with pytest.raises(ValueError, match="2 columns"):
        markdown_table(("a", "b"), [("only one",)])


def test_atomic_files_write_all_or_none_and_keep_other_files(tmp_path):
    from identify.files import atomic_files

    (tmp_path / "keep.txt").write_text("mine")
    (tmp_path / "a.txt").write_text("old a")
    with pytest.raises(RuntimeError), atomic_files(tmp_path) as staging:
        (staging / "a.txt").write_text("new a")
        (staging / "b.txt").write_text("new b")
        raise RuntimeError("fails half-way")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "keep.txt"]
    assert (tmp_path / "a.txt").read_text() == "old a"
    with atomic_files(tmp_path) as staging:
        (staging / "a.txt").write_text("new a")
        (staging / "b.txt").write_text("new b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt", "keep.txt"]
    assert (tmp_path / "a.txt").read_text() == "new a" and (tmp_path / "keep.txt").read_text() == "mine"


def test_atomic_files_removes_a_folder_it_created_when_it_fails(tmp_path):
    from identify.files import atomic_files

    target = tmp_path / "new" / "out"
    with pytest.raises(RuntimeError), atomic_files(target) as staging:
        (staging / "a.txt").write_text("a")
        raise RuntimeError("fails")
    assert not target.exists()


def test_atomic_files_gives_each_file_the_mode_of_a_new_file(tmp_path):
    from identify.files import atomic_files, current_umask

    with atomic_files(tmp_path) as staging:
        f = staging / "secretive.bin"
        f.write_bytes(b"x")
        os.chmod(f, 0o600)              # as tempfile.mkstemp would leave it
    assert stat.S_IMODE((tmp_path / "secretive.bin").stat().st_mode) == 0o666 & ~current_umask()
