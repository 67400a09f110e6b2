"""Robot time: the pace of a sample, the motion speed and the mechanical part of a session, and the
excitation poses' budget (light: the options read it; minutes and seconds as named)."""

from __future__ import annotations

#: Default budget of extra robot time, minutes (the 15-minute session plus at most 5).
DEFAULT_BUDGET_MINUTES = 5.0
#: Largest budget, minutes: a typo guard (an hour of extra poses is a new session, not an addition).
MAX_BUDGET_MINUTES = 60.0
#: The mechanical part of a session (tool tips and axes moves), minutes.
MECHANICAL_MINUTES = 5.0
#: Robot time per image sample (move, image, annotate), seconds: the paper's pace (about 10 s per sample).
SECONDS_PER_SAMPLE = 10.0
#: Fraction of the vendor's speed the robot moves at between poses.
SPEED_SCALE = 0.25
