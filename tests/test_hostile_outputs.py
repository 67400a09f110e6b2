"""Hostile outputs: every command that writes refuses to clobber, to write over special files, to give
two outputs one path, and leaves nothing behind when it fails, is interrupted or is killed.

The table runs in this process through :func:`hostile.check_refusal` (exit code 2, one line,
nothing changed in the folder); the tests below it need real processes (a second writer,
SIGTERM, a file-size limit) or a failure injected after part of the outputs were written.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from hostile import Case, check_refusal, run_cli, snapshot

from brachycal.data import read_pose_table

LOG = ROOT / "examples" / "joint_log.csv"
SESSION = ROOT / "examples" / "session_exact"
CONSOLE = [sys.executable, "-m", "brachycal.cli.main"]


# --- what a case puts in its folder first ---------------------------------------------------------
def existing(*names: str) -> Callable[[Path], None]:
    """Regular files (with content to keep) at ``names``, folders made as needed."""

    def setup(tmp: Path) -> None:
        for name in names:
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp / name).write_text("keep me\n")

    return setup


def copies(
    files: dict[str, Path], links: dict[str, str] | None = None, hard_links: dict[str, str] | None = None
) -> Callable[[Path], None]:
    """Copies of ``files`` (folders too) at the given names; symlinks and hard links ``name -> target``."""

    def setup(tmp: Path) -> None:
        for name, source in files.items():
            if source.is_dir():
                shutil.copytree(source, tmp / name)
            else:
                shutil.copyfile(source, tmp / name)
        for name, target in (links or {}).items():
            (tmp / name).symlink_to(target)
        for name, target in (hard_links or {}).items():
            (tmp / name).hardlink_to(tmp / target)

    return setup


def folder(*names: str) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        for name in names:
            (tmp / name).mkdir(parents=True)

    return setup


def fifo(name: str) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        os.mkfifo(tmp / name)

    return setup


def symlink_to_devnull(name: str) -> Callable[[Path], None]:
    def setup(tmp: Path) -> None:
        (tmp / name).symlink_to(os.devnull)

    return setup


def _sysfs_refuses_root() -> bool:
    """sysfs refuses new files even to root: the one EACCES a root test process can provoke."""
    try:
        (Path("/sys") / ".brachycal-probe").touch()
    except OSError:
        return Path("/sys").is_dir()
    (Path("/sys") / ".brachycal-probe").unlink()
    return False


FK = ["fk", "{log}", "--frames", "needle_tip", "--quiet"]
PLAN = ["plan", "--quiet"]
CALIBRATE = ["calibrate", "{session}", "--quiet"]
EXPORTS = "sda10f_calibrated.urdf", "ImageToProbe.tfm", "PlusCoordinateDefinitions.xml", "static_transforms.yaml"

CASES = [
    # fk: one file
    Case("fk-out-exists", [*FK, "--out", "{tmp}/p.csv"], ("p.csv", "already exists", "--force"), existing("p.csv")),
    Case(
        "fk-out-is-a-folder-even-with-force",
        [*FK, "--out", "{tmp}/p.csv", "--force"],
        ("is a folder",),
        folder("p.csv"),
    ),
    Case("fk-out-dev-null-even-with-force", [*FK, "--out", os.devnull, "--force"], ("/dev/null", "is a device")),
    Case("fk-out-fifo-even-with-force", [*FK, "--out", "{tmp}/p.csv", "--force"], ("p.csv", "FIFO"), fifo("p.csv")),
    Case(
        "fk-out-symlink-to-a-device",
        [*FK, "--out", "{tmp}/p.csv", "--force"],
        ("p.csv", "is a device"),
        symlink_to_devnull("p.csv"),
    ),
    Case("fk-folder-missing", [*FK, "--out", "{tmp}/no/p.csv"], ("no", "folder does not exist")),
    Case("fk-folder-is-a-file", [*FK, "--out", "{tmp}/f/p.csv"], ("f/p.csv", "not a folder"), existing("f")),
    Case(
        "fk-folder-unwritable-sysfs",
        [*FK, "--out", "/sys/brachycal-hostile.csv"],
        ("/sys/brachycal-hostile.csv", "permission denied"),
        marks=[pytest.mark.skipif(not _sysfs_refuses_root(), reason="/sys is writable or absent here")],
    ),
    # plan: plan, figure, infeasible points
    Case("plan-figure-would-be-the-plan", [*PLAN, "--out", "{tmp}/x.png"], ("x.png", "figure", "--out", "same file")),
    Case(
        "plan-figure-is-the-plan",
        [*PLAN, "--out", "{tmp}/p.csv", "--figure", "{tmp}/./p.csv"],
        ("p.csv", "--figure and --out", "same file"),
    ),
    Case("plan-figure-exists", [*PLAN, "--out", "{tmp}/p.csv"], ("p.png", "already exists"), existing("p.png")),
    Case(
        "plan-infeasible-list-exists",
        [*PLAN, "--out", "{tmp}/p.csv"],
        ("p_infeasible.csv", "already exists"),
        existing("p_infeasible.csv"),
    ),
    Case(
        "plan-figure-is-a-folder-even-with-force",
        [*PLAN, "--out", "{tmp}/p.csv", "--figure", "{tmp}/fig", "--force"],
        ("fig", "is a folder"),
        folder("fig"),
    ),
    # calibrate: result and --report folder
    Case(
        "calibrate-out-exists", [*CALIBRATE, "--out", "{tmp}/r.json"], ("r.json", "already exists"), existing("r.json")
    ),
    Case(
        "calibrate-report-exists",
        [*CALIBRATE, "--out", "{tmp}/r.json", "--report", "{tmp}/rep"],
        ("rep/report.html", "already exists", "--force"),
        existing("rep/report.html"),
    ),
    Case(
        "calibrate-report-figure-exists",
        [*CALIBRATE, "--out", "{tmp}/r.json", "--report", "{tmp}/rep"],
        ("rep/points_3d.png", "already exists"),
        existing("rep/points_3d.png"),
    ),
    Case(
        "calibrate-out-is-the-report",
        [*CALIBRATE, "--out", "{tmp}/rep/report.html", "--report", "{tmp}/rep"],
        ("report.html", "same file"),
        folder("rep"),
    ),
    Case(
        "calibrate-report-is-a-file",
        [*CALIBRATE, "--out", "{tmp}/r.json", "--report", "{tmp}/rep"],
        ("rep", "not a folder"),
        existing("rep"),
    ),
    Case("calibrate-out-dev-null", [*CALIBRATE, "--out", os.devnull, "--force"], ("/dev/null", "is a device")),
    # export: a folder of six files
    *(
        Case(
            f"export-{name}-exists",
            ["export", "{result}", "--out", "{tmp}/x"],
            (name, "already exists"),
            existing(f"x/{name}"),
        )
        for name in EXPORTS
    ),
    Case("export-out-is-a-file", ["export", "{result}", "--out", "{tmp}/x"], ("x", "not a folder"), existing("x")),
    Case(
        "export-one-file-is-a-folder-even-with-force",
        ["export", "{result}", "--out", "{tmp}/x", "--force"],
        ("ImageToProbe.tfm", "is a folder"),
        folder("x/ImageToProbe.tfm"),
    ),
    # pivot, nwire: one JSON file
    Case(
        "pivot-out-exists",
        ["pivot", "{poses}", "--out", "{tmp}/p.json"],
        ("p.json", "already exists"),
        existing("p.json"),
    ),
    Case(
        "pivot-out-fifo-even-with-force",
        ["pivot", "{poses}", "--out", "{tmp}/p.json", "--force"],
        ("FIFO",),
        fifo("p.json"),
    ),
    Case(
        "nwire-out-exists",
        ["nwire", "{config}", "{frames}", "--out", "{tmp}/n.json"],
        ("n.json", "already exists"),
        existing("n.json"),
    ),
    Case(
        "nwire-out-is-a-folder-even-with-force",
        ["nwire", "{config}", "{frames}", "--out", "{tmp}/n.json", "--force"],
        ("is a folder",),
        folder("n.json"),
    ),
    # study, design: output folders
    *(
        Case(f"study-{name}-exists", ["study", "--out", "{tmp}/s"], (name, "already exists"), existing(f"s/{name}"))
        for name in ("runs.csv", "summary.csv", "study.png")
    ),
    Case(
        "study-plot-is-a-folder-even-with-force",
        ["study", "--out", "{tmp}/s", "--force"],
        ("study.png", "is a folder"),
        folder("s/study.png"),
    ),
    Case("study-out-is-a-file", ["study", "--out", "{tmp}/s"], ("not a folder",), existing("s")),
    Case(
        "design-csv-exists", ["design", "--out", "{tmp}/d"], ("design.csv", "already exists"), existing("d/design.csv")
    ),
    Case(
        "design-csv-is-a-fifo-even-with-force",
        ["design", "--out", "{tmp}/d", "--force"],
        ("design.csv", "FIFO"),
        fifo("d/design.csv"),
    ),
    # demo: session, truth, result and report in one folder; --force is new
    Case(
        "demo-result-exists",
        ["demo", "--out", "{tmp}/d"],
        ("result.json", "already exists", "--force"),
        existing("d/result.json"),
    ),
    Case(
        "demo-truth-exists",
        ["demo", "--out", "{tmp}/d"],
        ("session/truth.json", "already exists"),
        existing("d/session/truth.json"),
    ),
    Case("demo-session-is-a-file", ["demo", "--out", "{tmp}/d"], ("d/session", "not a folder"), existing("d/session")),
    Case(
        "demo-figure-is-a-fifo-even-with-force",
        ["demo", "--out", "{tmp}/d", "--force"],
        ("fig10_points.png", "FIFO"),
        fifo("d/report/fig10_points.png"),
    ),
    # an output is never one of the command's inputs, --force or not (the same file, by any name)
    Case(
        "fk-out-is-its-log-even-with-force",
        ["fk", "{tmp}/log.csv", "--frames", "needle_tip", "--out", "{tmp}/log.csv", "--force", "--quiet"],
        ("log.csv", "one of the inputs", "--force"),
        copies({"log.csv": LOG}),
    ),
    Case(
        "fk-out-is-its-log-through-a-symlink",
        ["fk", "{tmp}/link.csv", "--frames", "needle_tip", "--out", "{tmp}/log.csv", "--force", "--quiet"],
        ("log.csv", "one of the inputs", "link.csv"),
        copies({"log.csv": LOG}, links={"link.csv": "log.csv"}),
    ),
    Case(
        "fk-out-is-its-times-file",
        ["fk", "{log}", "--frames", "needle_tip", "--times", "{tmp}/t.csv", "--out", "{tmp}/t.csv", "--force"],
        ("t.csv", "one of the inputs"),
        copies({"t.csv": LOG}),
    ),
    Case(
        "calibrate-out-is-its-samples-even-with-force",
        ["calibrate", "{tmp}/s", "--out", "{tmp}/s/samples.csv", "--force", "--quiet"],
        ("samples.csv", "one of the inputs"),
        copies({"s": SESSION}),
    ),
    Case(
        "calibrate-report-is-a-hard-link-to-its-touches",
        ["calibrate", "{tmp}/s", "--out", "{tmp}/r.json", "--report", "{tmp}/s", "--force", "--quiet"],
        ("report.html", "one of the inputs", "touches.csv"),
        copies({"s": SESSION}, hard_links={"s/report.html": "s/touches.csv"}),
    ),
    Case(
        "plan-out-is-its-result-refused-before-planning",
        ["plan", "--result", "{tmp}/r.json", "--out", "{tmp}/r.json", "--force", "--quiet"],
        ("r.json", "one of the inputs"),
        lambda tmp: (tmp / "r.json").write_text("{}\n"),  # never read: refused when claimed
    ),
    Case(
        "session-build-out-holds-its-template",
        [
            "session",
            "build",
            "{log}",
            "--marks",
            "{tmp}/m.csv",
            "--images",
            "{tmp}/i.csv",
            "--template",
            "{tmp}/s/session.toml",
            "--out",
            "{tmp}/s",
            "--force",
        ],
        ("session.toml", "one of the inputs"),
        copies({"s": SESSION}),
    ),
    # the command reads the input after claiming its outputs: refused when the set is committed
    Case(
        "pivot-out-is-its-poses",
        ["pivot", "{tmp}/p.csv", "--out", "{tmp}/p.csv", "--force"],
        ("p.csv", "one of the inputs"),
        copies({"p.csv": ROOT / "examples" / "pivot" / "pointer_pivot.csv"}),
    ),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Valid inputs, outside the cases' folders: a result file, a pivot pose list."""
    folder = tmp_path_factory.mktemp("inputs")
    result = folder / "result.json"
    assert run_cli(["calibrate", str(SESSION), "--out", str(result), "--quiet"]).code == 0
    rng = np.random.default_rng(3)
    rows = []
    for _ in range(12):  # a tool rotating about its tip (0.1 m from the marker) at a fixed pivot
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        R *= np.sign(np.linalg.det(R))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, np.array([0.2, 0.1, 0.3]) - R @ np.array([0.0, 0.0, 0.1])
        rows.append(",".join(repr(float(v)) for v in T.ravel()))
    poses = folder / "poses.csv"
    poses.write_text(",".join(f"m{i}{j}" for i in range(4) for j in range(4)) + "\n" + "\n".join(rows) + "\n")
    # The outputs are claimed before any input is read, so N-wire refusals need no PLUS files.
    config, frames = folder / "config.xml", folder / "frames.xml"
    config.write_text("<PlusConfiguration/>\n")
    frames.write_text("<TrackedFrameList/>\n")
    return {"log": LOG, "session": SESSION, "result": result, "poses": poses, "config": config, "frames": frames}


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id, marks=c.marks) for c in CASES])
def test_output_refusals(case, tmp_path, inputs):
    check_refusal(case, tmp_path, **inputs)


# --- real processes ---------------------------------------------------------------------------------
def long_log(path: Path, repeats: int) -> int:
    """The example joint log repeated ``repeats`` times end to end (a long recording); its samples."""
    lines = LOG.read_text().splitlines()
    header, rows = lines[0], [r.split(",", 1) for r in lines[1:]]
    step = float(rows[-1][0]) + 0.02
    with path.open("w") as handle:
        handle.write(header + "\n")
        for k in range(repeats):
            handle.writelines(f"{float(t) + k * step!r},{rest}\n" for t, rest in rows)
    return repeats * len(rows)


def wait_for(predicate: Callable[[], bool], process: subprocess.Popen, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert process.poll() is None, f"the command ended before {what}: {process.communicate()}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_a_second_writer_of_the_same_output_is_refused_and_the_first_file_is_complete(tmp_path):
    samples = long_log(tmp_path / "log.csv", 100)
    out = tmp_path / "poses.csv"
    argv = ["fk", str(tmp_path / "log.csv"), "--frames", "needle_tip,probe_tip", "--out", str(out), "--quiet"]
    first = subprocess.Popen([*CONSOLE, *argv, "--force"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for((tmp_path / ".poses.csv.brachycal-lock").exists, first, "the first writer's claim")
    # The first process now reads, computes and writes for seconds; the second starts meanwhile
    # (in this process: at once, so the two surely overlap), with --force: the claim refuses it.
    second = run_cli([*argv, "--force"])
    assert second.code == 2 and second.err.count("\n") == 1, second.err
    assert f"poses.csv: another brachycal process (pid {first.pid}) is writing it" in second.err
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    time_s, frames, _ = read_pose_table(out)  # complete: every row parses, none is missing
    assert len(time_s) == 2 * samples and frames[-2:] == ["needle_tip", "probe_tip"]
    assert hidden(tmp_path) == []
    # afterwards, without --force, the file is simply there
    third = run_cli(argv)
    assert third.code == 2 and "already exists; pass --force" in third.err


@pytest.mark.parametrize("moment", ["claimed", "writing"], ids=["while-computing", "mid-write"])
def test_sigterm_leaves_no_temporary_file_and_no_output(tmp_path, moment):
    long_log(tmp_path / "log.csv", 100)
    (tmp_path / "poses.csv").write_text("the previous run's\n")
    argv = ["fk", str(tmp_path / "log.csv"), "--frames", "needle_tip,probe_tip", "--out", "poses.csv", "--force"]
    before = snapshot(tmp_path)
    process = subprocess.Popen(
        [*CONSOLE, *argv, "--quiet"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    if moment == "claimed":
        wait_for((tmp_path / ".poses.csv.brachycal-lock").exists, process, "the claim")
    else:
        wait_for(lambda: any(tmp_path.glob(".poses.csv.brachycal-*.csv")), process, "the staged pose table")
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 143 and err.strip() == "brachycal: terminated", err
    assert snapshot(tmp_path) == before  # the old output untouched, no staging or lock file


def test_a_write_error_midway_is_one_line_naming_the_file_and_leaves_nothing(tmp_path):
    """Disk full, as the kernel reports it: a file-size limit makes the write fail (EFBIG)."""
    long_log(tmp_path / "log.csv", 20)
    before = snapshot(tmp_path)

    def limit() -> None:  # in the child only; Python ignores SIGXFSZ, so write() fails instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))

    argv = ["fk", "log.csv", "--frames", "needle_tip,probe_tip", "--out", "poses.csv", "--quiet"]
    done = subprocess.run(
        [*CONSOLE, *argv], cwd=tmp_path, capture_output=True, text=True, preexec_fn=limit, timeout=300
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr == "brachycal: error: poses.csv: cannot write the outputs (File too large)\n"
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("force", [False, True], ids=["new", "forced-over-old"])
def test_a_failure_after_part_of_the_set_was_written_leaves_the_folder_as_it_was(tmp_path, monkeypatch, force):
    """calibrate --report: the result and the first figures are staged, then the disk fills up."""
    import brachycal.reporting.html_report as html_report

    def disk_full(p_real, p_cal, path, title):
        Path(path).write_bytes(b"\x89PNG half a figure")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(html_report, "points_3d", disk_full)
    if force:
        existing("r.json", "rep/report.html", "rep/loo_histogram.png")(tmp_path)
    before = snapshot(tmp_path)
    argv = ["calibrate", str(SESSION), "--out", str(tmp_path / "r.json"), "--report", str(tmp_path / "rep"), "--quiet"]
    outcome = run_cli([*argv, *(["--force"] if force else [])])
    assert outcome.code == 2
    assert outcome.err == f"brachycal: error: {tmp_path}: cannot write the outputs (No space left on device)\n"
    assert snapshot(tmp_path) == before  # nothing new, nothing replaced, no folder made


# --- permissions: root ignores them, so the test drops to an unprivileged user -------------------------
@contextmanager
def unprivileged() -> Iterator[None]:
    """Run the block as ``nobody`` when this process is root (effective uid only; restored after).

    The interpreter's own files may be readable by root only (``/root/.pyenv``): the modules a
    command imports lazily are imported first, as root, by reading the inputs it will read.
    """
    from brachycal.data import read_joint_log
    from brachycal.data.session import read_session
    from brachycal.model import Robot

    robot = Robot.load()
    read_joint_log(LOG, robot)
    read_session(SESSION, robot)
    if os.geteuid() != 0:
        yield
        return
    os.setegid(65534)
    os.seteuid(65534)
    try:
        yield
    finally:
        os.seteuid(0)
        os.setegid(0)


@pytest.fixture
def shared_folder() -> Iterator[Path]:
    """A folder another user can enter (pytest's tmp_path is private to its owner)."""
    folder = Path(tempfile.mkdtemp(prefix="brachycal-perm-"))
    folder.chmod(0o755)
    yield folder
    for path in sorted(folder.rglob("*"), reverse=True):
        path.chmod(0o700)
        path.rmdir() if path.is_dir() else path.unlink()
    folder.rmdir()


def test_an_unwritable_folder_is_one_line_naming_the_output(shared_folder):
    locked = shared_folder / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    with unprivileged():
        outcome = run_cli(["fk", str(LOG), "--frames", "needle_tip", "--out", str(locked / "p.csv"), "--quiet"])
    assert outcome.code == 2
    assert outcome.err == f"brachycal: error: {locked / 'p.csv'}: cannot write here (Permission denied)\n"
    assert list(locked.iterdir()) == []


def test_an_unreadable_session_file_is_one_line_naming_it(shared_folder):
    session = shared_folder / "session"
    session.mkdir()
    for path in SESSION.iterdir():
        (session / path.name).write_bytes(path.read_bytes())
        (session / path.name).chmod(0o644)
    (session / "session.toml").chmod(0o000)
    out = shared_folder / "out"
    out.mkdir()
    out.chmod(0o777)  # the output may be written: only the input is refused
    with unprivileged():
        outcome = run_cli(["calibrate", str(session), "--out", str(out / "r.json"), "--quiet"])
    lines = outcome.err.splitlines()
    assert outcome.code == 2 and len(lines) == 1 and "Traceback" not in outcome.err, outcome.err
    assert lines[0].startswith("brachycal: error: ") and "session.toml" in lines[0]
    assert "permission denied" in lines[0].lower()
    assert list(out.iterdir()) == []


# --- after a hard kill, and locks of other users ------------------------------------------------------
def test_after_kill_9_the_next_run_removes_the_stale_staging_file(tmp_path):
    long_log(tmp_path / "log.csv", 100)
    argv = [*CONSOLE, "fk", "log.csv", "--frames", "needle_tip,probe_tip", "--out", "poses.csv", "--quiet"]
    process = subprocess.Popen(argv, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wait_for(lambda: any(tmp_path.glob(".poses.csv.brachycal-*.csv")), process, "the staged pose table")
    process.kill()
    process.wait()
    left = hidden(tmp_path)
    assert any(name.endswith(".csv") for name in left) and ".poses.csv.brachycal-lock" in left, left
    done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert hidden(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "poses.csv"]


#: ``calibrate --report`` in a child that stops, with its outputs claimed and the result and the
#: first figure staged, at the report's 3D figure: it prints "staged" and waits to be killed.
STOPPED_AT_THE_REPORT = """
import sys
import brachycal.reporting.html_report as html_report
from brachycal.cli.main import main

def stop(*args, **kwargs):
    print("staged", flush=True)
    sys.stdin.read()

html_report.points_3d = stop
sys.exit(main(sys.argv[1:]))
"""


def test_after_kill_9_during_calibrate_report_no_visible_folder_is_left(tmp_path):
    """The report's folder is staged as a hidden sibling: SIGKILL leaves only hidden entries,
    which the next run of the same command removes."""
    argv = ["calibrate", str(SESSION), "--out", "r.json", "--report", "rep", "--quiet"]
    process = subprocess.Popen(
        [sys.executable, "-c", STOPPED_AT_THE_REPORT, *argv],
        cwd=tmp_path,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    assert "staged\n" in iter(process.stdout.readline, ""), process.communicate()  # the tables print first
    process.kill()
    process.communicate()
    assert [p.name for p in tmp_path.iterdir() if not p.name.startswith(".")] == []
    assert ".rep.brachycal-lock" in hidden(tmp_path)  # what a hard kill can leave: hidden, stale
    done = subprocess.run([*CONSOLE, *argv], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert hidden(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "rep"]
    assert hidden(tmp_path / "rep") == [] and (tmp_path / "rep" / "report.html").is_file()


def test_export_onto_a_disk_with_no_room_at_all_leaves_nothing(tmp_path, inputs):
    """No byte can be written (a file-size limit of 0, as a full disk: the lock file is made but
    its holder's pid cannot be written, nor any output): one line, nothing left, no folder."""

    def no_room() -> None:  # in the child only; Python ignores SIGXFSZ, so write() fails instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))

    done = subprocess.run(
        [*CONSOLE, "export", str(inputs["result"]), "--out", "x"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        preexec_fn=no_room,
        timeout=300,
    )
    assert done.returncode == 2, done.stderr
    assert list(tmp_path.iterdir()) == []
    assert done.stderr == f"brachycal: error: {tmp_path / 'x'}: cannot write the outputs (File too large)\n"


def test_a_stale_staging_file_of_another_output_is_left_alone(tmp_path):
    """Only the claimed destination's own staging files are stale for its writer."""
    others = [".q.csv.brachycal-0123abcd.csv", ".poses.csv.brachycal-0123abcd.csv.brachycal-89abcdef.csv"]
    for name in [*others, ".poses.csv.brachycal-0123abcd.csv", ".poses.csv.brachycal-0123abcd-old"]:
        (tmp_path / name).write_text("left by a killed writer\n")
    outcome = run_cli(["fk", str(LOG), "--frames", "needle_tip", "--out", str(tmp_path / "poses.csv"), "--quiet"])
    assert outcome.code == 0, outcome.err
    assert hidden(tmp_path) == sorted(others)


def test_a_stale_lock_of_another_user_is_taken_over(shared_folder):
    """A lock file root left (its writer killed) in a folder both may write: not "Permission denied"."""
    shared_folder.chmod(0o777)
    lock = shared_folder / ".p.csv.brachycal-lock"
    lock.write_text("12345\n")
    lock.chmod(0o644)
    with unprivileged():
        outcome = run_cli(["fk", str(LOG), "--frames", "needle_tip", "--out", str(shared_folder / "p.csv"), "--quiet"])
    assert outcome.code == 0, outcome.err
    assert sorted(p.name for p in shared_folder.iterdir()) == ["p.csv"]


def test_a_held_lock_of_another_user_names_the_writer(shared_folder):
    import fcntl

    shared_folder.chmod(0o777)
    lock = shared_folder / ".p.csv.brachycal-lock"
    lock.write_text("12345\n")
    lock.chmod(0o644)
    with lock.open("r") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        with unprivileged():
            outcome = run_cli(["fk", str(LOG), "--frames", "needle_tip", "--out", str(shared_folder / "p.csv")])
    assert outcome.code == 2
    assert (
        outcome.err
        == f"brachycal: error: {shared_folder / 'p.csv'}: another brachycal process (pid 12345) is writing it\n"
    )
    assert sorted(p.name for p in shared_folder.iterdir()) == [lock.name]


@contextmanager
def small_disk(folder: Path, size: str) -> Iterator[bool]:
    """A tmpfs of ``size`` at ``folder`` if this process may mount one (yields True), else nothing."""
    folder.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], capture_output=True)
    try:
        yield mounted.returncode == 0
    finally:
        if mounted.returncode == 0:
            subprocess.run(["umount", str(folder)], check=True)


def test_a_full_disk_during_export_leaves_nothing_and_names_the_output(tmp_path, inputs, monkeypatch):
    """The meshes fill the disk: no folder, no staging or lock file is left; the message names a
    mesh output, not the robot description being copied from."""
    disk = tmp_path / "disk"
    with small_disk(disk, "300k") as real:
        if not real:  # no tmpfs: the copy fails as a full disk makes it fail
            import brachycal.export.formats as formats

            def full(source, target, *args):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

            monkeypatch.setattr(formats.shutil, "copyfileobj", full)
        outcome = run_cli(["export", str(inputs["result"]), "--out", str(disk / "x")])
        assert outcome.code == 2, outcome.err
        assert outcome.err.startswith(f"brachycal: error: {disk / 'x' / 'meshes'}/"), outcome.err
        assert outcome.err.endswith(": cannot write (No space left on device)\n"), outcome.err
        assert list(disk.iterdir()) == []


def test_a_read_only_file_system_is_named_at_the_output_not_its_staging_file(tmp_path):
    disk = tmp_path / "ro"
    with small_disk(disk, "100k") as real:
        if real:
            subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
        else:
            disk.chmod(0o555)
        with unprivileged() if not real else contextlib.nullcontext():
            outcome = run_cli(["fk", str(LOG), "--frames", "needle_tip", "--out", str(disk / "p.csv"), "--quiet"])
        reason = "Read-only file system" if real else "Permission denied"
        assert outcome.err == f"brachycal: error: {disk / 'p.csv'}: cannot write here ({reason})\n"
        assert outcome.code == 2
