"""Hostile input to ``brachycal temporal``: each refused in one line naming the option, file, frame
or element, exit code 2, nothing written.

The inputs are the small synthetic water-tank recording of :mod:`brachycal.studies.tank_recording`, spoiled one way
per row: no line in the frames, a probe that does not move, a tracker reading that is not rigid,
a device set with a malformed clip rectangle, options out of range.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.studies.tank_recording import write_tank_recording

RUN = ["temporal", "{tmp}/video.mha", "{tmp}/tracker.mha", "--out", "{tmp}/lag.json"]


def recording(**options):
    def setup(tmp: Path) -> None:
        write_tank_recording(tmp, **options)

    return setup


def with_file(name: str, text: str, **options):
    def setup(tmp: Path) -> None:
        write_tank_recording(tmp, **options)
        (tmp / name).write_text(text)

    return setup


def config(attributes: str) -> str:
    return f"<PlusConfiguration><vtkPlusTemporalCalibrationAlgo {attributes} /></PlusConfiguration>"


SHEARED = np.array([[1.0, 0.3, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])

CASES = [
    Case("no-pose-stream", ["temporal", "{tmp}/video.mha", "--out", "{tmp}/lag.json"], ("TRACKER", "--joints"),
         recording()),
    Case("both-pose-streams", [*RUN, "--joints", "{tmp}/log.csv"], ("not both",), recording()),
    Case("config-with-joints", ["temporal", "{tmp}/video.mha", "--joints", "{tmp}/log.csv", "--config",
                                "{tmp}/c.xml", "--out", "{tmp}/lag.json"], ("--config",), recording()),
    Case("clip-three-numbers", [*RUN, "--clip", "1,2,3"], ("--clip",), recording()),
    Case("clip-outside-image", [*RUN, "--clip", "100,10,100,50"], ("clip rectangle", "video.mha"), recording()),
    Case("negative-max-lag", [*RUN, "--max-lag-s", "-0.5"], ("--max-lag-s",), recording()),
    Case("nan-resolution", [*RUN, "--resolution-s", "nan"], ("--resolution-s",), recording()),
    Case("resolution-above-range", [*RUN, "--max-lag-s", "0.1", "--resolution-s", "0.2"], ("resolution",),
         recording()),
    Case("video-missing", RUN, ("video.mha",), lambda tmp: None),
    Case("video-not-metaimage", RUN, ("video.mha",), with_file("video.mha", "hello\n")),
    Case("frames-without-line", RUN, ("video.mha", "tank bottom", "0 of 120", "frame 0"), recording(blank=True)),
    Case("video-without-timestamps", RUN, ("Timestamp", "video.mha"), recording(timestamps=False)),
    Case("probe-still", RUN, ("tracker.mha", "probe moves 0.0 mm"), recording(still=True)),
    Case("tracker-sheared", RUN, ("tracker.mha", "ProbeToTrackerTransform"), recording(probe_matrix=SHEARED)),
    Case("tracker-unknown-tool", [*RUN, "--probe", "NeedleToTracker"], ("NeedleToTracker",), recording()),
    Case("lag-beyond-search", [*RUN, "--max-lag-s", "0.05"], ("edge of the search range",),
         recording(lag_s=0.3)),
    Case("config-bad-clip", [*RUN, "--config", "{tmp}/c.xml"], ("c.xml", "ClipRectangleOrigin"),
         with_file("c.xml", config('ClipRectangleOrigin="a b" ClipRectangleSize="10 10"'))),
    Case("config-clip-half", [*RUN, "--config", "{tmp}/c.xml"], ("c.xml", "ClipRectangleSize"),
         with_file("c.xml", config('ClipRectangleOrigin="1 1"'))),
    Case("config-bad-lag", [*RUN, "--config", "{tmp}/c.xml"], ("c.xml", "MaximumMovingLagSec"),
         with_file("c.xml", config('MaximumMovingLagSec="-1"'))),
    Case("config-not-xml", [*RUN, "--config", "{tmp}/c.xml"], ("c.xml", "XML"), with_file("c.xml", "<a>")),
    Case("out-exists", RUN, ("lag.json", "exists"), with_file("lag.json", "{}")),
]  # fmt: skip


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_refused(case, tmp_path):
    check_refusal(case, tmp_path)
