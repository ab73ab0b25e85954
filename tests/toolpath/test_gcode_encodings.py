"""G-code reader: file encodings (UTF-8 with/without BOM, Latin-1 comments) and visible error text."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identify.errors import InputError
from simulate.toolpath.gcode import parse_program, read_program

PROGRAMS = Path(__file__).parent / "programs"
PLAIN = "G21 G90\nG0 X1 Y2 Z5\nG1 Z0 F100\nG1 X11\n"


def _ends(prog):
    return [tuple(np.round(s.end * 1e3, 9)) for s in prog.segments]


def test_utf8_with_and_without_bom_read_the_same(tmp_path):
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    a.write_bytes(PLAIN.encode("utf-8"))
    b.write_bytes(b"\xef\xbb\xbf" + PLAIN.encode("utf-8"))
    # by hand: rapid to (1,2,5) mm, feed down to z 0, feed to x 11
    assert _ends(read_program(a)) == _ends(read_program(b)) == [(1, 2, 5), (1, 2, 0), (11, 2, 0)]
    # the service hands over text that may still start with the BOM character
    assert _ends(parse_program("\ufeff" + PLAIN)) == _ends(read_program(a))


def test_error_on_the_first_line_of_a_bom_file_shows_no_invisible_character(tmp_path):
    f = tmp_path / "bom.nc"
    f.write_bytes(b"\xef\xbb\xbfG21 G90 X\n")
    with pytest.raises(InputError) as ei:
        read_program(f)
    msg = str(ei.value)
    assert (ei.value.line, ei.value.column) == (1, 9)  # columns count from after the BOM
    assert "\ufeff" not in msg and all(ch.isprintable() for ch in msg)


@pytest.mark.parametrize("bad, shown", [("\u200b", "U+200B"), ("\ufeff", "U+FEFF"), ("\x07", "U+0007")])
def test_invisible_character_in_a_line_is_named_by_its_code_point(bad, shown):
    with pytest.raises(InputError) as ei:
        parse_program(f"G21\nG1 X1 F10{bad}Y2\n", source="z.nc")
    e = ei.value
    assert (e.line, e.column) == (2, 10)
    assert shown in str(e) and bad not in str(e)


def test_latin1_comments_are_read_and_line_numbers_stay_true():
    prog = read_program(PROGRAMS / "latin1_comments.nc")
    # by hand: rapid (0,0,5), feed to z -1 at 200 mm/min, feed to x 20, rapid up to z 5
    assert _ends(prog) == [(0, 0, 5), (0, 0, -1), (20, 0, -1), (20, 0, 5)]
    assert [s.line for s in prog.segments] == [5, 6, 7, 8]  # byte 0x85 in line 3 is no line break
    assert prog.segments[1].feed == pytest.approx(0.2 / 60)


def test_latin1_file_with_an_error_names_its_line(tmp_path):
    data = (PROGRAMS / "latin1_comments.nc").read_bytes().replace(b"G0 Z5.\n", b"G0 Z5.\nG1 X21 Y\n")
    f = tmp_path / "bad.nc"
    f.write_bytes(data)
    with pytest.raises(InputError) as ei:
        read_program(f)
    assert (ei.value.line, ei.value.column) == (9, 8) and "has no number" in str(ei.value)


@pytest.mark.parametrize("data, words, line", [
    (b"G21\nG1 X1\x00 F10\n", ["not a text file", "NUL"], 2),
    ("G21\nG1 X1 F10\n".encode("utf-16"), ["not a text file", "UTF-16"], None),
])
def test_binary_and_wide_files_are_not_text(tmp_path, data, words, line):
    f = tmp_path / "w.nc"
    f.write_bytes(data)
    with pytest.raises(InputError) as ei:
        read_program(f)
    for w in words:
        assert w in str(ei.value)
    assert ei.value.line == line
    if line is not None:
        assert ei.value.column == 6


def test_bom_before_latin1_bytes_is_dropped_too(tmp_path):
    # a BOM written by one editor, a Latin-1 comment by another: not UTF-8 as a whole
    f = tmp_path / "mixed.nc"
    f.write_bytes(b"\xef\xbb\xbfG21 G90 (Fr\xe4ser)\nG0 X1\n")
    prog = read_program(f)
    assert _ends(prog) == [(1, 0, 0)]


# 10 in Arabic-Indic, Devanagari and full-width digits
@pytest.mark.parametrize("digits", ["\u0661\u0660", "\u0967\u0966", "\uff11\uff10"])
def test_digits_outside_ascii_are_no_number(digits):
    """Python's float() reads these as 10; a G-code number is ASCII digits only."""
    with pytest.raises(InputError) as ei:
        parse_program(f"G21 G90\nS10000 M3\nG1 X{digits} F100\n", source="p.nc")
    assert ei.value.line == 3 and "'X'" in str(ei.value)
