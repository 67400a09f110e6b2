"""The one way in for input files (:mod:`brachycal.inputs`): regular files only, sizes capped, every
input recorded; and every reader of brachycal goes through it."""

from __future__ import annotations

import os
import re
import socket
from pathlib import Path

import pytest
from conftest import ROOT

from brachycal.errors import InputError
from brachycal.inputs import (
    check_input_file,
    check_memory,
    input_at,
    open_input,
    read_input_bytes,
    read_input_text,
    recording_inputs,
)


def test_a_regular_file_and_a_symlink_to_one_are_read(tmp_path: Path) -> None:
    (tmp_path / "a.csv").write_bytes(b"time\n1\n")
    (tmp_path / "link.csv").symlink_to("a.csv")
    assert read_input_bytes(tmp_path / "link.csv", max_bytes=100) == b"time\n1\n"
    with open_input(tmp_path / "a.csv", "r") as handle:
        assert handle.read() == "time\n1\n"


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda path: os.mkfifo(path), "is a FIFO (named pipe), not a regular file"),
        (lambda path: path.mkdir(), "is a folder; expected a file"),
        (lambda path: path.symlink_to("/dev/zero"), "is a device, not a regular file"),
        (lambda path: socket.socket(socket.AF_UNIX).bind(str(path)), "is a socket, not a regular file"),
        (lambda path: None, "no such file"),
    ],
    ids=["fifo", "folder", "symlink-to-dev-zero", "socket", "missing"],
)
def test_anything_but_a_regular_file_is_refused_without_reading_it(tmp_path: Path, make, words: str) -> None:
    path = tmp_path / "bad"
    make(path)
    for read in (
        lambda: check_input_file(path),
        lambda: open_input(path),  # a FIFO without a writer: opening it would block
        lambda: read_input_bytes(path, max_bytes=10),
    ):
        with pytest.raises(InputError, match=re.escape(f"{path}: {words}")):
            read()


def test_a_folder_is_accepted_where_one_may_be_given(tmp_path: Path) -> None:
    assert check_input_file(tmp_path, folder_ok=True).st_ino == tmp_path.stat().st_ino


def test_a_file_larger_than_its_kind_may_be_is_refused_before_reading(tmp_path: Path) -> None:
    path = tmp_path / "big.json"
    path.write_bytes(b"x" * 2_000_001)
    with pytest.raises(InputError, match=r"big.json: is larger than 1.91 MB \(2000001 bytes\), the most"):
        read_input_bytes(path, max_bytes=2_000_000)
    with pytest.raises(InputError, match=r"is larger than 10 bytes \(11 bytes\)"):
        path.write_bytes(b"x" * 11)
        read_input_text(path, max_bytes=10)


def test_a_utf8_byte_order_mark_is_dropped_and_bad_utf8_is_the_callers_to_name(tmp_path: Path) -> None:
    path = tmp_path / "a.toml"
    path.write_bytes(b"\xef\xbb\xbfformat = 1\n")
    assert read_input_text(path, max_bytes=100) == "format = 1\n"
    path.write_bytes(b"\xff\n")
    with pytest.raises(UnicodeDecodeError):
        read_input_text(path, max_bytes=100)


def test_inputs_read_while_recording_are_known_by_inode(tmp_path: Path) -> None:
    (tmp_path / "a.csv").write_text("x\n")
    (tmp_path / "hard.csv").hardlink_to(tmp_path / "a.csv")
    (tmp_path / "b.csv").write_text("x\n")
    read_input_bytes(tmp_path / "a.csv", max_bytes=10)  # not recorded: no command is running
    assert input_at(tmp_path / "a.csv") is None
    with recording_inputs():
        read_input_bytes(tmp_path / "a.csv", max_bytes=10)
        assert input_at(tmp_path / "hard.csv") == str(tmp_path / "a.csv")
        assert input_at(tmp_path / "b.csv") is None and input_at(tmp_path / "missing") is None
    assert input_at(tmp_path / "a.csv") is None


def test_an_allocation_larger_than_half_the_memory_is_refused(monkeypatch) -> None:
    import brachycal.inputs

    monkeypatch.setattr(brachycal.inputs, "memory_bytes", lambda: 8 << 30)
    check_memory(4 << 30, "pixel data", file="f.mha")
    with pytest.raises(InputError, match=r"f.mha: pixel data would take 4.1e\+03 MB, more than half"):
        check_memory((4 << 30) + 1, "pixel data", file="f.mha")


#: Reading a file by another way than :mod:`brachycal.inputs`: what the guard below looks for.
RAW_READ = re.compile(
    r"\.read_text\(|\.read_bytes\(|(?<![\w.])open\(|\.open\((?!\"w)|ET\.parse\(|tomllib\.load\(|loadtxt|"
    r"genfromtxt|np\.fromfile|trimesh\.load\("
)

#: The reads that are not of a user's input: (file, what the line holds).
NOT_INPUTS = {
    ("_lazy.py", "read_text"): "brachycal's own source",
    ("reporting/html_report.py", "read_bytes"): "a figure this command just staged",
    ("studies/example_files.py", "read_text"): "bundled data",
    ("model/robot.py", "trimesh.load("): "a mesh checked by check_input_file first",
    ("export/formats.py", 'with open(os.path.join(share, "urdf"'): "text of a generated launch file",
    ("data/formats/bag_records.py", "reader.open()"): "rosbags, after _check_bag_files",
}


def test_every_reader_of_an_input_file_goes_through_the_inputs_module() -> None:
    """A new reader that opens a file itself (and would read /dev/zero forever) fails here."""
    source = ROOT / "src" / "brachycal"
    found = []
    for path in sorted(source.rglob("*.py")):
        name = str(path.relative_to(source))
        if name == "inputs.py":
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#")[0]
            if not RAW_READ.search(code) or re.search(r"\bopen\([^)]*\"w|os\.open\(|fdopen|\.open\(\"w", code):
                continue
            if line.lstrip().startswith(("``", '"', "float parser")):
                continue  # prose
            if any(name == file and what in line for file, what in NOT_INPUTS):
                continue
            found.append(f"{name}:{number}: {line.strip()}")
    assert found == []
