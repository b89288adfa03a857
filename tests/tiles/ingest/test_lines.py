"""tiles.ingest.lines: the line parser that survives damaged lines."""
from __future__ import annotations

import numpy as np
import pytest

from tiles.ingest.lines import LineError, parse_block, repair_line


def test_clean_block_parses_fast_path():
    vals, st = parse_block(b"1 2 3 4 5 6\n7.5 8 9 10 11 12\n", 6, " ")
    np.testing.assert_array_equal(vals, [[1, 2, 3, 4, 5, 6], [7.5, 8, 9, 10, 11, 12]])
    assert (st.points, st.repaired, st.skipped_control, st.blank) == (2, 0, 0, 0)


def test_control_characters_are_repaired_or_skipped_and_counted():
    buf = (b"1 2 3 10 20 30\n"
           b"4 5 6 185\x00187 183\n"          # NUL where a space was: read as a separator
           b"-9.1\x160 1 2 3 4 5\n"            # inside a number: removed
           b"\x10\n"                           # a lone control character: skipped
           b"7 8 9 103.0\x100000 1 1\n"
           b"\n"                               # blank
           b"10 11 12 1 2 3")                  # no final newline
    vals, st = parse_block(buf, 6, " ")
    np.testing.assert_array_equal(vals, [[1, 2, 3, 10, 20, 30], [4, 5, 6, 185, 187, 183], [-9.1, 1, 2, 3, 4, 5],
                                         [7, 8, 9, 103, 1, 1], [10, 11, 12, 1, 2, 3]])
    assert (st.points, st.repaired, st.skipped_control, st.blank) == (5, 3, 1, 1)
    assert [w for _, w in st.examples][:2] == ["control characters read as a separator", "control characters removed"]


def test_repair_line_gives_up_on_unreadable_lines():
    assert repair_line(b"\x10", 6) == (None, "control characters only")
    fixed, what = repair_line(b"1 2 x\x003 4 5 6", 6)
    assert fixed is None and "unreadable" in what


def test_bad_line_is_an_error_with_its_position_unless_skipped():
    buf = b"1 2 3 4 5 6\n1 2 3 4 5\n7 8 9 1 1 1\n"
    with pytest.raises(LineError, match="5 fields, expected 6") as e:
        parse_block(buf, 6, " ")
    assert e.value.pos == 12
    vals, st = parse_block(buf, 6, " ", policy="skip")
    assert len(vals) == 2 and st.skipped_bad == 1
    vals, st = parse_block(b"1 2 3 4 5 6\n1 2 abc 4 5 6\n", 6, " ", policy="skip")
    assert len(vals) == 1 and st.skipped_bad == 1


@pytest.mark.parametrize("text", [b"1 2 nan 4 5 6\n", b"1 2 inf\t4 5 6\n", b"1,2,-inf,4,5,6\n"])
def test_non_finite_values_are_always_errors(text):
    with pytest.raises(LineError, match="not a finite number"):
        parse_block(b"0 0 0 0 0 0\n" + text, 6, " ", policy="skip")


def test_separators_whitespace_comma_tabs_and_crlf():
    for buf in (b"1,2,3\n4, 5, 6\n", b"1  2 3\n4\t5 6\r\n", b"1 2 3\r\n4 5 6\r\n"):
        vals, _ = parse_block(buf, 3, "," if b"," in buf else " ")
        np.testing.assert_array_equal(vals, [[1, 2, 3], [4, 5, 6]])
