"""``brachycal plan``: the sample grid (the default), ``plan check`` (the poses of a check before each
procedure) and ``plan excitation`` (extra poses that identify the robot), with the options they share.

Each sub-command is its own command of the command line (``plan-check``, ``plan-excitation``): the
words ``plan check`` name it (:data:`SUBCOMMANDS`). The spellings of an earlier release,
``plan --verify`` and ``plan --excitation SESSION``, still run them, with a one-line note
(:func:`current_spelling`).
"""

from __future__ import annotations

from collections.abc import Sequence

from brachycal.cli.common import earlier_spelling, spelling_note

#: ``brachycal plan WORD``: the command each word names.
SUBCOMMANDS = {"check": "plan-check", "excitation": "plan-excitation"}
#: Options of ``plan --verify`` renamed in ``plan check``.
_RENAMED = {"--verify-poses": "--poses", "--verify-touches": "--touches"}


def current_spelling(arguments: Sequence[str]) -> list[str]:
    """``arguments`` (after ``brachycal``) with an earlier release's spelling of a ``plan`` sub-command
    replaced by the current one: ``plan --verify [--verify-poses N] [--verify-touches T] …`` is
    ``plan check [--poses N] [--touches T] …`` and ``plan --excitation SESSION …`` is
    ``plan excitation SESSION …``. Says so on stderr, in one line. Anything else: unchanged."""
    arguments = list(arguments)
    at = earlier_spelling(arguments, "plan", SUBCOMMANDS)
    if at is None:
        return arguments
    head, rest = arguments[:at], arguments[at + 1 :]
    if "--verify" in rest:
        rest.remove("--verify")
        renamed = []
        for word in rest:
            name, eq, value = word.partition("=")
            renamed.append(_RENAMED.get(name, name) + eq + value if name in _RENAMED else word)
        spelling_note("plan --verify", "plan check")
        return [*head, SUBCOMMANDS["check"], *renamed]
    for k, word in enumerate(rest):
        if word == "--excitation" and k + 1 < len(rest):
            spelling_note("plan --excitation SESSION", "plan excitation SESSION")
            return [*head, SUBCOMMANDS["excitation"], rest[k + 1], *rest[:k], *rest[k + 2 :]]
        if word.startswith("--excitation="):
            spelling_note("plan --excitation SESSION", "plan excitation SESSION")
            return [*head, SUBCOMMANDS["excitation"], word.partition("=")[2], *rest[:k], *rest[k + 1 :]]
    return arguments
