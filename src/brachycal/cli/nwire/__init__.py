"""``brachycal nwire``: N-wire phantom calibration of a tracked probe (``nwire calibrate``, the default,
so ``brachycal nwire CONFIG FRAMES`` runs it) and ``nwire segment`` (the phantom's points in tracked
B-mode sequences), one command group.

Each sub-command is its own command of the command line (``nwire``, ``nwire-segment``): the words
``nwire calibrate`` and ``nwire segment`` name it (:data:`SUBCOMMANDS`). An earlier release's
spelling, ``brachycal nwire-segment``, still runs it, with a one-line note (:func:`current_spelling`).
"""

from __future__ import annotations

from collections.abc import Sequence

from brachycal.cli.common import spelling_note

#: ``brachycal nwire WORD``: the command each word names (``calibrate`` is also the default).
SUBCOMMANDS = {"calibrate": "nwire", "segment": "nwire-segment"}


def current_spelling(arguments: Sequence[str]) -> list[str]:
    """``arguments`` (after ``brachycal``) unchanged; if they spell ``nwire segment`` as an earlier release
    did, ``nwire-segment``, says on stderr (one line) that it is now ``nwire segment``."""
    arguments = list(arguments)
    first = next((word for word in arguments if not word.startswith("-")), None)
    if first == SUBCOMMANDS["segment"]:
        spelling_note("nwire-segment", "nwire segment")
    return arguments
