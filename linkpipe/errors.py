"""Errors that reach the user as one clear message (exit status 2, no traceback)."""
from __future__ import annotations

import difflib


class LinkpipeError(Exception):
    """A problem the user can fix; the CLI prints ``str(err)`` and exits 2."""


class SceneError(LinkpipeError):
    """A bad scene: names the file, the table and key, what is wrong and what to do.

    ``table`` is the TOML table as written (``"points"``, ``"links[2]"``, ``"drivers[1].input"``),
    ``key`` the offending key (may be ``None`` for a whole table), ``hint`` what to do.
    """

    def __init__(self, path, table: str, key: str | None, message: str, hint: str = ""):
        self.path = str(path)
        self.table = table
        self.key = key
        self.message = message
        self.hint = hint
        where = f"[{table}]" if table else "(top level)"
        if key is not None:
            where += f" {key}"
        text = f"{self.path}: {where}: {message}"
        if hint:
            text += f" — {hint}"
        super().__init__(text)


def did_you_mean(word: str, choices) -> str:
    """Return a ' did you mean "x"?' phrase for the closest of ``choices``, or a list of them."""
    choices = [str(c) for c in choices]
    close = difflib.get_close_matches(str(word), choices, n=1, cutoff=0.5)
    if close:
        return f'did you mean "{close[0]}"?'
    if choices:
        return "valid: " + ", ".join(f'"{c}"' for c in choices)
    return ""


class MemoryRefused(SceneError):
    """A sweep refused before any work because it would need more memory than is available:
    the scene's mistake (fewer steps), never a failed trial or a failed row of a study."""
