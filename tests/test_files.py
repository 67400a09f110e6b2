"""The output writer (``brachycal.io``): all or nothing, never clobbered, claimed, no NaN in JSON."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from brachycal.errors import OutputError
from brachycal.io import OutputSet, atomic_open, atomic_path, json_text, staged_destination, write_json


def listing(folder: Path) -> list[str]:
    """Every entry below ``folder``, hidden ones (staging and lock files) included."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


class Boom(BaseException):
    """Stands for KeyboardInterrupt / the CLI's Terminated: not an Exception."""


def test_outputs_appear_together_only_when_the_set_is_committed(tmp_path):
    with OutputSet() as out:
        a = out.claim(tmp_path / "a.csv")
        b = out.claim(tmp_path / "sub" / "b.png", make_parents=True)
        # staged next to the destination (same folder: the final rename is atomic), hidden,
        # keeping the suffix (matplotlib picks the format from it); a new folder is staged whole
        # as a hidden sibling, renamed into place at the commit
        assert a.parent == tmp_path and a.name.startswith(".a.csv.") and a.suffix == ".csv"
        assert b.parent.parent == tmp_path and b.parent.name.startswith(".sub.brachycal-") and b.suffix == ".png"
        a.write_text("A")
        b.write_text("B")
        assert not (tmp_path / "a.csv").exists() and not (tmp_path / "sub").exists()
    assert (tmp_path / "a.csv").read_text() == "A" and (tmp_path / "sub" / "b.png").read_text() == "B"
    assert out.written == [tmp_path / "a.csv", tmp_path / "sub" / "b.png"]
    assert listing(tmp_path) == ["a.csv", "sub", "sub/b.png"]  # no staging or lock file left


@pytest.mark.parametrize("failure", [RuntimeError("bug"), KeyboardInterrupt(), Boom()], ids=type)
def test_any_failure_removes_every_staged_file_lock_and_created_folder(tmp_path, failure):
    (tmp_path / "old.csv").write_text("keep")
    with pytest.raises(type(failure)), OutputSet(force=True) as out:
        out.claim(tmp_path / "old.csv").write_text("new")
        out.claim(tmp_path / "new" / "deeper" / "x.csv", make_parents=True).write_text("x")
        raise failure
    assert listing(tmp_path) == ["old.csv"]
    assert (tmp_path / "old.csv").read_text() == "keep"


def test_a_new_folder_is_never_visible_before_the_commit(tmp_path):
    """The folders an output needs appear with it: a killed command leaves no visible folder."""
    with OutputSet() as out:
        out.claim(tmp_path / "rep" / "report.html", make_parents=True).write_text("<html/>")
        out.claim(tmp_path / "rep" / "figures" / "a.png", make_parents=True).write_text("png")
        out.claim(tmp_path / "other" / "b.csv", make_parents=True).write_text("b")
        assert [p.name for p in tmp_path.iterdir() if not p.name.startswith(".")] == []
    assert listing(tmp_path) == ["other", "other/b.csv", "rep", "rep/figures", "rep/figures/a.png", "rep/report.html"]


def test_a_folder_made_at_the_destination_while_the_command_ran_is_kept(tmp_path):
    made = r"rep: already exists \(made while it was being written\)"
    with pytest.raises(OutputError, match=made), OutputSet() as out:
        out.claim(tmp_path / "a.csv").write_text("ours")
        out.claim(tmp_path / "rep" / "r.html", make_parents=True).write_text("ours")
        (tmp_path / "rep").mkdir()
        (tmp_path / "rep" / "theirs.txt").write_text("someone else's")
    assert listing(tmp_path) == ["rep", "rep/theirs.txt"]


def test_a_disk_too_full_for_the_lock_holders_pid_still_locks_and_leaves_nothing(tmp_path, monkeypatch):
    """On a full disk the lock file is made (no data block) but its pid cannot be written."""
    import brachycal.io as io_module

    def full(fd: int, data: bytes) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(io_module.os, "write", full)
    with pytest.raises(OutputError, match=r"x/a.urdf: cannot write the outputs \(No space left on device\)"):
        with OutputSet() as out:
            out.claim(tmp_path / "x" / "a.urdf", make_parents=True)
            assert (tmp_path / ".x.brachycal-lock").exists()  # held all the same
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # the first write of an output
    assert listing(tmp_path) == []


def test_never_replaces_without_force(tmp_path):
    (tmp_path / "a.csv").write_text("keep")
    with pytest.raises(OutputError, match=r"a\.csv: already exists; pass force=True to replace it") as refused:
        with OutputSet() as out:
            out.claim(tmp_path / "a.csv")
    # A Python caller is told the keyword; the command line spells the same advice as its option.
    assert "--force" not in str(refused.value) and "--force" not in refused.value.problem
    assert refused.value.spelled("--force").endswith("a.csv: already exists; pass --force to replace it")
    assert listing(tmp_path) == ["a.csv"] and (tmp_path / "a.csv").read_text() == "keep"
    with OutputSet(force=True) as out:
        out.claim(tmp_path / "a.csv").write_text("new")
    assert (tmp_path / "a.csv").read_text() == "new"


def test_a_file_made_at_the_destination_while_the_command_ran_is_not_replaced(tmp_path):
    with pytest.raises(OutputError, match="made while it was being written"), OutputSet() as out:
        out.claim(tmp_path / "a.csv").write_text("ours")
        out.claim(tmp_path / "b.csv").write_text("ours")
        (tmp_path / "b.csv").write_text("someone else's")
    # all or nothing: a.csv, moved first, is taken back; b.csv is the other program's
    assert listing(tmp_path) == ["b.csv"] and (tmp_path / "b.csv").read_text() == "someone else's"


def test_a_failed_commit_puts_the_old_files_back(tmp_path):
    for name in ("a.csv", "b.csv"):
        (tmp_path / name).write_text(f"old {name}")
    with pytest.raises(OutputError, match="is a folder"), OutputSet(force=True) as out:
        out.claim(tmp_path / "a.csv").write_text("new")
        out.claim(tmp_path / "b.csv").write_text("new")
        (tmp_path / "b.csv").unlink()
        (tmp_path / "b.csv").mkdir()  # b.csv can no longer be replaced: the commit fails after a.csv
    assert (tmp_path / "a.csv").read_text() == "old a.csv"
    assert listing(tmp_path) == ["a.csv", "b.csv"]


@pytest.mark.parametrize("kind", ["folder", "fifo", "device", "symlink to a device"])
def test_special_files_are_refused_even_with_force(tmp_path, kind):
    target = tmp_path / "out"
    if kind == "folder":
        target.mkdir()
    elif kind == "fifo":
        os.mkfifo(target)
    elif kind == "symlink to a device":
        target.symlink_to(os.devnull)
    else:
        target = Path(os.devnull)
    word = {"folder": "is a folder", "fifo": r"is a FIFO \(named pipe\)"}.get(kind, "is a device")
    before = listing(tmp_path)
    with pytest.raises(OutputError, match=f"{word}; an output must be a regular file"), OutputSet(force=True) as out:
        out.claim(target)
    assert listing(tmp_path) == before


def test_folders_are_created_only_when_asked(tmp_path):
    with pytest.raises(OutputError, match="folder does not exist"), OutputSet() as out:
        out.claim(tmp_path / "no" / "a.csv")
    (tmp_path / "file").write_text("")
    with pytest.raises(OutputError, match="not a folder"), OutputSet() as out:
        out.claim(tmp_path / "file" / "a.csv", make_parents=True)
    assert listing(tmp_path) == ["file"]


def test_two_outputs_of_one_command_cannot_share_a_path(tmp_path):
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    for a, b in [("x.png", "./x.png"), ("real/x.csv", "link/x.csv")]:
        with pytest.raises(OutputError, match="--figure and --out of this command are the same file"):
            with OutputSet() as out:
                out.claim(tmp_path / a, label="--out")
                out.claim(tmp_path / b, label="--figure")
    assert listing(tmp_path) == ["link", "real"]


def test_a_second_writer_of_the_same_file_is_refused(tmp_path):
    with OutputSet() as first:
        first.claim(tmp_path / "a.csv").write_text("first")
        # flock locks belong to an open file, so a second claim in this process stands for
        # another process (tests/test_hostile_outputs.py does it with two processes)
        with pytest.raises(OutputError, match=rf"another brachycal process \(pid {os.getpid()}\) is writing it"):
            with OutputSet(force=True) as second:
                second.claim(tmp_path / "a.csv")
    assert (tmp_path / "a.csv").read_text() == "first"
    assert listing(tmp_path) == ["a.csv"]


def test_a_lock_left_by_a_killed_process_is_taken_over(tmp_path):
    (tmp_path / ".a.csv.brachycal-lock").write_text("12345\n")  # nobody holds it: its process died
    with OutputSet() as out:
        out.claim(tmp_path / "a.csv").write_text("A")
    assert listing(tmp_path) == ["a.csv"]


def test_the_release_of_an_output_keeps_the_existing_file(tmp_path):
    (tmp_path / "b.csv").write_text("old")
    with OutputSet(force=True) as out:
        out.claim(tmp_path / "a.csv").write_text("A")
        out.claim(tmp_path / "b.csv").write_text("partial")
        out.release(tmp_path / "b.csv")
    assert (tmp_path / "b.csv").read_text() == "old" and listing(tmp_path) == ["a.csv", "b.csv"]


def test_an_output_the_command_did_not_write_fails_the_commit(tmp_path):
    with pytest.raises(OutputError, match="was not written"), OutputSet() as out:
        out.claim(tmp_path / "a.csv").write_text("A")
        out.claim(tmp_path / "b.csv")
    assert listing(tmp_path) == []


def test_os_errors_of_writing_name_the_destination_not_the_staging_file(tmp_path):
    with pytest.raises(OutputError) as caught, OutputSet() as out:
        staged = out.claim(tmp_path / "a.csv")
        raise OSError(errno.ENOSPC, "No space left on device", str(staged))
    assert str(caught.value) == f"{tmp_path / 'a.csv'}: cannot write (No space left on device)"
    # a buffered write that fails at close carries no file name: the set names its outputs
    with pytest.raises(OutputError) as caught, OutputSet() as out:
        out.claim(tmp_path / "a.csv")
        raise OSError(errno.EFBIG, "File too large")
    assert str(caught.value) == f"{tmp_path / 'a.csv'}: cannot write the outputs (File too large)"
    # an error reading an input is not the outputs' business
    with pytest.raises(FileNotFoundError), OutputSet() as out:
        out.claim(tmp_path / "a.csv")
        (tmp_path / "missing.csv").read_text()
    assert listing(tmp_path) == []


def test_one_file_writers_join_a_set_or_stand_alone(tmp_path):
    with OutputSet() as out:
        staged = out.claim(tmp_path / "a.txt")
        assert staged_destination(staged) == tmp_path / "a.txt"
        with atomic_open(staged) as handle:  # a library writer given the staging path writes it
            handle.write("in the set")
        assert listing(tmp_path) == sorted([".a.txt.brachycal-lock", staged.name])
    assert staged_destination(staged) is None
    with atomic_open(tmp_path / "b.txt") as handle:  # alone: its own one-file set
        handle.write("alone")
    with pytest.raises(OutputError, match="already exists"), atomic_path(tmp_path / "b.txt") as path:
        path.write_text("never")
    assert (tmp_path / "a.txt").read_text() == "in the set" and (tmp_path / "b.txt").read_text() == "alone"
    assert listing(tmp_path) == ["a.txt", "b.txt"]


def test_json_never_holds_nan_or_infinity_and_the_error_names_the_key(tmp_path):
    assert json_text({"a": [1.0, 2]}) == '{\n  "a": [\n    1.0,\n    2\n  ]\n}\n'
    for value, shown in [(float("nan"), "nan"), (float("inf"), "inf"), (-float("inf"), "-inf")]:
        payload = {"format": "x", "loocv": {"icp": {"errors_mm": [0.1, value]}}}
        with pytest.raises(OutputError, match=rf"out\.json: loocv\.icp\.errors_mm\[1\] is {shown}, not a finite"):
            write_json(tmp_path / "out.json", payload)
    assert listing(tmp_path) == []
