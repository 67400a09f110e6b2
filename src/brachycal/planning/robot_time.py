"""The excitation poses' robot-time budget: its default and range (light: the options read it)."""

from __future__ import annotations

#: Default budget of extra robot time, minutes (issue 19: the 15-minute session plus at most 5).
DEFAULT_BUDGET_MINUTES = 5.0
#: Largest budget, minutes: a typo guard (an hour of extra poses is a new session, not an addition).
MAX_BUDGET_MINUTES = 60.0
