"""One grammar for the numbers of every file and option: what CSV and text writers write (Python's
``repr``, ``%.17g``, the csv module, ``numpy.savetxt``), and nothing that Python's ``float`` takes
besides (``0_1`` as 1, ``0x10``, blanks, non-ASCII digits, ``infinity``); and a file whose last line
has no newline (a writer cut off mid-number: ``1.608151017`` left as ``1.60``) refused by every reader.
"""

from __future__ import annotations

import csv
import io
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, reference
from hypothesis import given
from hypothesis import strategies as st

from brachycal.cli.common import output_file
from brachycal.data import read_times
from brachycal.data.formats.csv_log import TRUNCATED, csv_log_blocks, read_table, table_blocks, to_float
from brachycal.data.formats.joint_table import read_joint_table, still_table_kind
from brachycal.data.pose_list import read_pose_list
from brachycal.errors import InputError
from brachycal.validate import (
    all_number_texts,
    check_positions,
    check_token,
    number_from_text,
    numbers_from_text,
    parse_number_list,
    whole_from_text,
)

WRITTEN = [
    "0",
    "-0.0",
    "1.608151017",
    "+2.5",
    "1e-05",
    "1E+300",
    "-1.7976931348623157e+308",
    "5e-324",
    ".5",
    "7.",
    "0001.50",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "-Inf",
]
NOT_NUMBERS = [
    "0_1",  # Python's digit separator: float() reads 1
    "2_5",
    "1_000.5",
    "0x10",
    "0b1",
    " 1",
    "1 ",
    "\t1",
    "1\n",
    "\u00a01",  # no-break space
    "1e",
    "1e+",
    "e5",
    ".",
    "-",
    "+-1",
    "1.2.3",
    "1,5",
    "1.5f",
    "1d5",
    "\u0661",  # ARABIC-INDIC DIGIT ONE: float() reads 1
    "\u0661\u0662",
    "\uff11",  # FULLWIDTH DIGIT ONE
    "infinity",  # float() takes it; no writer writes it
    "-Infinity",
    "nan(123)",
    "",
]


@pytest.mark.parametrize("text", WRITTEN)
def test_the_numbers_writers_write_are_read_as_float_reads_them(text):
    x = number_from_text(text)
    assert x is not None
    assert x == float(text) or (math.isnan(x) and math.isnan(float(text)))


@pytest.mark.parametrize("text", NOT_NUMBERS)
def test_text_that_float_may_take_but_no_writer_writes_is_refused(text):
    assert number_from_text(text) is None
    assert not all_number_texts(["1.0", text, "2.0"])


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_every_finite_float_written_by_repr_or_17_digits_reads_back_equal(x):
    assert number_from_text(repr(x)) == x
    assert number_from_text(f"{x:.17g}") == x
    assert number_from_text(str(np.float64(x))) == x


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=8))
def test_rows_written_by_the_csv_module_and_savetxt_read_back_equal(values):
    text = io.StringIO()
    csv.writer(text).writerow(values)
    fields = next(csv.reader([text.getvalue()]))
    assert all_number_texts(fields)
    assert [number_from_text(f) for f in fields] == values
    for fmt in ("%.18e", "%.17g", "%.9f"):
        saved = io.StringIO()
        np.savetxt(saved, np.array([values]), fmt=fmt, delimiter=",")
        assert saved.getvalue().endswith("\n")
        fields = saved.getvalue().rstrip("\n").split(",")
        assert all_number_texts(fields)
        assert [number_from_text(f) for f in fields] == [float(f) for f in fields]


def test_blank_separated_lists_and_whole_numbers():
    assert numbers_from_text(" 1 0\t-2.5e3 \n") == [1.0, 0.0, -2500.0]
    assert numbers_from_text("1 0_1") is None
    assert whole_from_text("-42") == -42
    for text in ("4_2", "\u0664\u0662", "0x10", "1.0", " 4", "1e3"):
        assert whole_from_text(text) is None


def test_options_allow_blanks_around_items_but_not_other_junk():
    assert parse_number_list(" 1, 2 ,3", "--x") == [1.0, 2.0, 3.0]
    with pytest.raises(InputError, match=r"--x value 2 must be a number, got '2_0'"):
        parse_number_list("1,2_0", "--x")
    with pytest.raises(InputError, match="--n must be a whole number, got '\u0661'"):
        parse_number_list("\u0661", "--n", kind=int)


# --- tables -----------------------------------------------------------------------------------------


def table(tmp_path: Path, text: str, name: str = "t.csv") -> Path:
    path = tmp_path / name
    path.write_bytes(text.encode())
    return path


def floats(path: Path, columns: list[str]) -> np.ndarray:
    header, rows, records = read_table(path, columns)
    return to_float(path, header, rows, records, columns)


def test_a_table_of_written_numbers_reads_as_written(tmp_path):
    path = table(tmp_path, "a,b\r\n1.5,-2e-3\r\n.5,7.\r\n")  # CRLF line ends, as Windows writers end lines
    assert floats(path, ["a", "b"]).tolist() == [[1.5, -0.002], [0.5, 7.0]]


@pytest.mark.parametrize(
    ("field", "message"),
    [
        ("0_1", r"row 3, column 'b': '0_1' is not a number"),
        ("1 5", r"row 3, column 'b': '1 5' is not a number"),  # a blank inside, not around
        ("\u00a01", r"row 3, column 'b': '\\xa01' is not a number"),  # a no-break space is no blank
        ("infinity", r"row 3, column 'b': 'infinity' is not a number"),
        ("inf", r"row 3, column 'b': value is not a finite number, got 'inf'"),
        ("nan", r"row 3, column 'b': value is not a finite number, got 'nan'"),
        ("1e999", r"row 3, column 'b': value is not a finite number, got '1e999'"),
        ('"1\n2"', r"row 4, column 'b': '1\\n2' is not a number"),  # a quoted line break, ending on line 4
    ],
)
def test_a_field_that_is_not_a_finite_number_is_named(tmp_path, field, message):
    path = table(tmp_path, f"a,b\n1,2\n3,{field}\n")
    with pytest.raises(InputError, match=message):
        floats(path, ["a", "b"])


def spreadsheet_and_savetxt_tables(values: np.ndarray, header: list[str]) -> dict[str, str]:
    """``values`` as other tools write a table: NumPy's ``savetxt(..., delimiter=", ")``, a
    spreadsheet's export (byte-order mark, CRLF, blanks either side of the separators), old Mac
    line ends (CR alone)."""
    saved = io.StringIO()
    np.savetxt(saved, values, fmt="%.17g", delimiter=", ", header=", ".join(header), comments="")
    rows = [" , ".join(header)] + [" , ".join(f"{x!r} " for x in row) for row in values.tolist()]
    return {
        "savetxt": saved.getvalue(),
        "spreadsheet": "\ufeff" + "\r\n".join(rows) + "\r\n",
        "cr-only": "\r".join([",".join(header), *(",".join(repr(x) for x in row) for row in values.tolist())]) + "\r",
    }


@pytest.mark.parametrize("origin", ["savetxt", "spreadsheet", "cr-only"])
def test_a_table_with_blanks_around_its_fields_reads_as_numpy_reads_it(tmp_path, origin):
    values = np.random.default_rng(7).normal(size=(6, 3)) * [1.0, 1e-3, 1e3]
    path = tmp_path / "t.csv"
    path.write_bytes(spreadsheet_and_savetxt_tables(values, ["a", "b", "c"])[origin].encode())
    read = floats(path, ["a", "b", "c"])
    assert np.array_equal(read, values)
    oracle = np.loadtxt(path, delimiter=",", skiprows=1, encoding="utf-8-sig") if origin != "cr-only" else values
    assert np.array_equal(read, oracle)


@pytest.mark.parametrize("cut", ["a,b\n1,2\n3,4.6", "a,b\n1,2\n3,", "a,b\n1,2\n3", "a,b"])
def test_a_table_whose_last_line_has_no_newline_is_refused_naming_that_row(tmp_path, cut):
    path = table(tmp_path, cut)
    row = cut.count("\n") + 1
    with pytest.raises(InputError, match=rf"t\.csv, row {row}: {TRUNCATED}"):
        read_table(path, ["a"])


def test_a_last_line_of_blanks_without_newline_holds_no_number_and_is_accepted(tmp_path):
    path = table(tmp_path, "a,b\n1,2\n  ")
    assert floats(path, ["a", "b"]).tolist() == [[1.0, 2.0]]


def test_times_file_cut_or_empty_is_refused(tmp_path):
    with pytest.raises(InputError, match="no times"):
        read_times(table(tmp_path, "time\n"))
    with pytest.raises(InputError, match=TRUNCATED):
        read_times(table(tmp_path, "time\n0.1\n0.2"))
    assert read_times(table(tmp_path, "time\n0.1\n0.2\n")).tolist() == [0.1, 0.2]


# --- joint logs, block by block (the fast pyarrow path and the row scan) ------------------------------


def log_text(robot, rows: int = 40) -> tuple[str, list[str]]:
    names = list(robot.joint_names)
    lines = [",".join(["time", *names])]
    lines += [",".join([repr(0.01 * k), *(repr(0.001 * k) for _ in names)]) for k in range(rows)]
    return "\n".join(lines) + "\n", names


@pytest.mark.parametrize("block_bytes", [None, 700])
def test_a_log_cut_mid_number_is_refused_in_every_block_size(tmp_path, robot, block_bytes):
    text, _ = log_text(robot)
    path = table(tmp_path, text[:-5], "log.csv")  # '0.039' of the last row cut to '0.0', no newline
    with pytest.raises(InputError, match=rf"log\.csv, row 41: {TRUNCATED}"):
        list(csv_log_blocks(path, robot, block_bytes=block_bytes))


def test_a_quoted_log_cut_mid_number_is_refused_by_the_row_scan(tmp_path, robot):
    text, _ = log_text(robot)
    lines = text.splitlines()
    lines[1] = lines[1].replace("0.0", '"0.0"', 1)  # a quote sends the rest of the log to the row scan
    path = table(tmp_path, "\n".join(lines)[:-2], "log.csv")
    with pytest.raises(InputError, match=rf"row 41: {TRUNCATED}"):
        list(csv_log_blocks(path, robot, block_bytes=700))


@pytest.mark.parametrize(
    ("field", "message"),
    [
        ("0 .5", r"'0 \.5' is not a number"),  # a blank inside a field: its block goes to the row scan
        ("0_5", r"'0_5' is not a number"),
        ("inf", r"value is not a finite number, got 'inf'"),  # pyarrow reads it: refused after
        ("1e999", r"value is not a finite number, got '1e999'"),
    ],
)
@pytest.mark.parametrize("block_bytes", [None, 700])
def test_a_bad_number_in_a_log_is_named_whatever_the_path(tmp_path, robot, field, message, block_bytes):
    text, names = log_text(robot)
    lines = text.splitlines()
    fields = lines[30].split(",")
    fields[3] = field
    lines[30] = ",".join(fields)
    path = table(tmp_path, "\n".join(lines) + "\n", "log.csv")
    with pytest.raises(InputError, match=rf"row 31, column '{names[2]}': {message}"):
        list(csv_log_blocks(path, robot, block_bytes=block_bytes))


@pytest.mark.parametrize("origin", ["savetxt", "spreadsheet"])
@pytest.mark.parametrize("block_bytes", [None, 700])
def test_a_log_with_blanks_around_its_fields_reads_as_written(tmp_path, robot, origin, block_bytes):
    """Both paths (pyarrow's blocks and the row scan): the same numbers as the plain log's."""
    text, names = log_text(robot)
    plain = table(tmp_path, text, "plain.csv")
    values = np.loadtxt(plain, delimiter=",", skiprows=1)
    path = tmp_path / "log.csv"
    path.write_bytes(spreadsheet_and_savetxt_tables(values, ["time", *names])[origin].encode())
    blocks = list(csv_log_blocks(path, robot, block_bytes=block_bytes))
    expected = list(csv_log_blocks(plain, robot, block_bytes=block_bytes))
    assert np.array_equal(np.concatenate([q for _, q in blocks]), np.concatenate([q for _, q in expected]))
    assert np.array_equal(np.concatenate([b.time for b, _ in blocks]), values[:, 0])


def test_a_log_with_old_mac_line_ends_is_refused_in_one_line_naming_them(tmp_path, robot):
    text, _ = log_text(robot)
    path = table(tmp_path, text.replace("\n", "\r"), "log.csv")
    with pytest.raises(InputError, match=r"log\.csv: its lines end in a carriage return alone"):
        list(csv_log_blocks(path, robot))


@pytest.mark.parametrize("origin", ["savetxt", "spreadsheet", "cr-only"])
def test_a_joint_table_without_header_reads_the_same_from_other_writers(tmp_path, robot, origin):
    """``fk``'s headerless tables: told from a log by their first line, whatever the line ends."""
    q = np.zeros((4, len(robot.joint_names))) + np.arange(4)[:, None] * 1e-3
    plain = table(tmp_path, "".join(",".join(repr(x) for x in row) + "\n" for row in q.tolist()), "plain.csv")
    text = spreadsheet_and_savetxt_tables(q, robot.joint_names)[origin]
    other = table(tmp_path, text.split("\n", 1)[1] if origin == "savetxt" else text.split("\r", 1)[1].lstrip("\n"))
    assert still_table_kind(other) == "no header"
    assert np.array_equal(read_joint_table(other, robot).q, read_joint_table(plain, robot).q)


# --- the files brachycal ships and reads --------------------------------------------------------------


def test_bundled_tables_end_with_a_newline():
    tables = [p for folder in ("examples", "src/brachycal") for p in (ROOT / folder).rglob("*.csv")]
    assert tables
    for path in tables:
        assert path.read_bytes().endswith(b"\n"), path


def test_the_outside_pivot_recording_still_reads():
    names, T, rows = read_pose_list(reference("sksurgery_pivot", "tracked_pointer_pivot.csv"))
    assert len(names) == len(T) == len(rows) == 1151


# --- range checks and names ---------------------------------------------------------------------------


def test_positions_beyond_the_physical_bound_are_refused_naming_row_and_column():
    P = np.array([[0.1, 0.2, 0.3], [0.1, 1e308, 0.3]])
    assert check_positions(P[:1], "p", limit=10.0, unit="m") is not None
    with pytest.raises(InputError, match=r"t\.csv, row 7, column 'y': p 1e\+308 m is beyond ±10 m"):
        check_positions(P, "p", limit=10.0, unit="m", file="t.csv", rows=[6, 7], columns=["x", "y", "z"])
    with pytest.raises(InputError, match="p nan is beyond"):
        check_positions([math.nan], "p", limit=10.0, unit="m")


@pytest.mark.parametrize("name", ["g,203", 'g"203', "g'203", "g\n203", "g 203", "g\t203", ""])
def test_a_sample_name_must_be_a_plain_token(name):
    with pytest.raises(InputError, match="not a plain token"):
        check_token(name, "sample")


@pytest.mark.parametrize("name", ["g203", "frame12", "s-1.a", "rtip_2"])
def test_plain_tokens_round_trip_through_a_csv_field(name):
    assert check_token(name, "sample") == name
    text = io.StringIO()
    csv.writer(text).writerow([name, 1.5])
    assert text.getvalue() == f"{name},1.5\r\n"  # written as it is, no quoting
    assert next(csv.reader([text.getvalue()])) == [name, "1.5"]


@pytest.mark.parametrize("text", ["out/", "a/b/", "/"])
def test_an_output_file_named_with_a_trailing_separator_is_refused(text):
    import argparse

    with pytest.raises(argparse.ArgumentTypeError, match="names a folder"):
        output_file(text)
    assert output_file("out/poses.csv") == "out/poses.csv"


def test_checking_many_fields_at_once_holds_no_memory_per_field():
    """A block of a long table is 262,144 fields: the one-pass check holds its joined text only."""
    fields = [repr(float(x)) for x in np.random.default_rng(2).normal(size=100_000)]
    tracemalloc.start()
    try:
        assert all_number_texts(fields)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    text_bytes = sum(len(f) + 1 for f in fields)
    assert peak < 2 * text_bytes + 100_000, f"peak {peak / 1e6:.1f} MB for {text_bytes / 1e6:.1f} MB of text"


@pytest.mark.parametrize("rows_per_block", [1, 3, 4, 5, None])
def test_a_table_read_in_blocks_is_the_table_read_whole(tmp_path, rows_per_block):
    path = table(tmp_path, "a,b\n1,2\n\n3,4\n5,6\n7,8\n")
    whole = read_table(path, ["a"])
    blocks = list(table_blocks(path, ["a"], rows_per_block))
    assert all(header == whole[0] for header, _, _ in blocks)
    assert [r for _, rows, _ in blocks for r in rows] == whole[1] == [2, 4, 5, 6]
    assert [f for _, _, records in blocks for f in records] == whole[2]
    cut = table(tmp_path, "a,b\n1,2\n3,4\n5,6\n7,8", "cut.csv")  # no newline at the end, 4 rows
    with pytest.raises(InputError, match=rf"cut\.csv, row 5: {TRUNCATED}"):
        list(table_blocks(cut, ["a"], rows_per_block))
