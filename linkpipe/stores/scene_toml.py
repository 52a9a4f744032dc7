"""A scene's own TOML text with some of its numbers replaced (a fit's fitted values, a search's
best design): comments and layout kept (tomlkit), each changed line marked with what it was,
the ``[[logs]]`` file paths rewritten to work from the output folder."""
from __future__ import annotations

import os
import pathlib

import tomlkit
from tomlkit.items import Array, InlineTable

from . import atomic_path


def with_values(scene, changes, out_dir, tag: str) -> str:
    """The text of ``scene`` with each ``(path, value)`` of ``changes`` put in place (``path``:
    keys and indices into its TOML, as :func:`linkpipe.fit.locate` gives them); each line that
    changed ends in ``# <tag>: <what> was <old>`` (its old comment, which may no longer hold,
    replaced); log paths relative to ``out_dir``."""
    doc = tomlkit.parse(scene.text)
    notes: dict[int, tuple] = {}
    for path, value in changes:
        items = [doc]
        for key in path[:-1]:
            items.append(items[-1][key])
        old = items[-1][path[-1]]
        old = old.unwrap() if hasattr(old, "unwrap") else old
        items[-1][path[-1]] = float(value)
        # the line's item: the outermost inline table or array on the way, else the value
        inline = next((i for i in range(1, len(items)) if isinstance(items[i], (InlineTable, Array))),
                      None)
        owner = items[inline] if inline is not None else items[-1][path[-1]]
        inner = path[inline:] if inline is not None else ()
        what = "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in inner).lstrip(".")
        _, said = notes.setdefault(id(owner), (owner, []))
        said.append(f"{what + ' ' if what else ''}was {old:.12g}" if isinstance(old, (int, float))
                    else f"{what + ' ' if what else ''}was {old}")
    for owner, said in notes.values():
        owner.comment(f"{tag}: {', '.join(said)}")
    for entry, log in zip(doc.get("logs", []), scene.logs):
        entry["file"] = os.path.relpath(log.path, pathlib.Path(out_dir))
    return tomlkit.dumps(doc)


def write(text: str, path) -> None:
    """``text`` to ``path``, whole or not at all."""
    with atomic_path(path, len(text.encode()) + 4096) as tmp:
        pathlib.Path(tmp).write_text(text)
