"""Net files for the console: opening, saving and exporting, inside one folder (paper section 5).

The console reads and writes net files only inside its *root* folder (the folder ``petrobot
console`` was started in, unless told otherwise): :func:`inside` turns a path the page sent into a
path under the root or refuses it (``..``, absolute paths elsewhere, symbolic links leading out,
suffixes other than ``.toml``/``.pnml``/``.xml``). :func:`open_net` gives a file's draft (with its
positions, or a first drawing from :func:`~coordinator.web.autolayout.layered_layout`) and its
problems; :func:`save_draft` writes a draft in one step (a temporary file renamed over the old
one); :func:`export_draft` converts a draft to PNML, DOT or canonical TOML.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from coordinator.errors import NetError
from coordinator.netfile import dump_net
from coordinator.netfile.formats import SUFFIXES
from coordinator.netfile.layout import load_layout
from coordinator.netfile.loader import read_text
from coordinator.web.autolayout import layered_layout
from coordinator.web.draft import (
    draft_layout,
    draft_of_net,
    draft_of_text,
    validate_draft,
    validate_text,
)
from services.errors import PetrobotError
from services.textfile import write_atomically

__all__ = ["FileRefused", "export_draft", "inside", "is_net_file", "list_nets", "open_net", "save_draft", "with_layout"]

#: Most net files :func:`list_nets` lists.
MAX_LISTED = 500


class FileRefused(PetrobotError):
    """A path the console will not read or write (outside its folder, wrong suffix, unreadable)."""


def inside(root: Path, path: str, *, suffixes: tuple[str, ...] = SUFFIXES) -> Path:
    """Resolve ``path`` (relative to ``root``, or absolute) to a file under ``root``.

    Raises:
        FileRefused: the path leaves the root (after following links), or has another suffix.
    """
    if not path or "\x00" in path:
        raise FileRefused("no file name")
    base = root.resolve()
    candidate = (base / path).resolve()
    if candidate != base and base not in candidate.parents:
        raise FileRefused(f"{path}: the console reads and writes files under {base} only")
    if candidate.suffix.lower() not in suffixes:
        raise FileRefused(f"{path}: use one of {', '.join(suffixes)}")
    return candidate


#: A TOML file is listed as a net when its first bytes hold a ``[net]`` table or a ``[[place]]``.
_TOML_NET = re.compile(rb"^[ \t]*(\[net\]|\[\[place\]\])", re.MULTILINE)
#: How much of a file :func:`is_net_file` reads, bytes.
SNIFF_BYTES = 64 * 1024


def is_net_file(path: Path) -> bool:
    """Whether ``path`` looks like a net file (a TOML net, or PNML): what Open lists, not
    ``services.toml`` or ``pyproject.toml``."""
    try:
        with path.open("rb") as f:
            head = f.read(SNIFF_BYTES)
    except OSError:
        return False
    if path.suffix.lower() == ".toml":
        return _TOML_NET.search(head) is not None
    return b"<pnml" in head[:8192]


def list_nets(root: Path) -> list[str]:
    """Net files under ``root`` (relative paths, sorted; hidden folders and ``.venv`` skipped; files
    that are not nets — ``services.toml``, ``pyproject.toml``, other XML — left out)."""
    base = root.resolve()
    found: list[str] = []
    for folder, dirs, files in os.walk(base):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d not in ("node_modules", "__pycache__"))
        for name in sorted(files):
            path = Path(folder) / name
            if path.suffix.lower() in SUFFIXES and not name.startswith(".") and is_net_file(path):
                found.append(str(path.relative_to(base)))
                if len(found) >= MAX_LISTED:
                    return found
    return found


def with_layout(draft: dict[str, Any]) -> dict[str, Any]:
    """Give every place and transition of a draft a position (laid out when missing)."""
    have = draft_layout(draft)
    ids = [p["id"] for p in draft.get("places", []) if isinstance(p.get("id"), str)]
    ids += [t["id"] for t in draft.get("transitions", []) if isinstance(t.get("id"), str)]
    if all(i in have for i in ids):
        return draft
    arcs = [(str(a.get("from")), str(a.get("to"))) for a in draft.get("arcs", [])]
    marked = [p["id"] for p in draft.get("places", []) if isinstance(p.get("tokens"), int) and p["tokens"] > 0]
    pos = layered_layout(ids, arcs, first=marked, fixed=have)
    for key in ("places", "transitions"):
        for item in draft.get(key, []):
            ident = item.get("id")
            if isinstance(ident, str) and ident not in have:
                item["pos"] = [round(pos[ident][0], 1), round(pos[ident][1], 1)]
    return draft


def open_net(path: Path, location: Any = None, *, shown_as: str | None = None) -> dict[str, Any]:
    """Open a net file for the page.

    Returns:
        ``{"path", "name", "draft", "validation", "laid_out"}``: the draft (every node with a
        position; ``laid_out`` tells whether the file had none), and the checks of
        :func:`~coordinator.web.draft.validate_draft` (the messages name ``shown_as``).

    Raises:
        FileRefused: the file cannot be read, or is not a net file that opens.
    """
    name = shown_as or path.name
    text = None
    try:
        if path.suffix.lower() == ".toml":
            text = read_text(path)
            draft = draft_of_text(text)
        else:
            from coordinator.netfile.pnml import load_pnml

            draft = draft_of_net(load_pnml(path, interpreted=False), load_layout(path))
    except NetError as exc:
        raise FileRefused(f"{name}: {exc.problem if exc.line is None else f'line {exc.line}: {exc.problem}'}") \
            from None
    had = bool(draft_layout(draft))
    draft = with_layout(draft)
    # the file's own problems at the file's own lines (what petrobot check FILE says)
    validation = validate_text(text, name, draft, location) if text is not None else \
        validate_draft(draft, name, location, lines=False)
    return {"path": shown_as or str(path), "name": name, "draft": draft, "validation": validation.to_json(),
            "laid_out": not had}


def save_draft(draft: dict[str, Any], target: Path, location: Any = None, *, shown_as: str | None = None
               ) -> dict[str, Any]:
    """Write a draft to ``target`` in one step; a valid net is written in the canonical form with
    its positions, a draft with problems as drawn (so nothing is lost).

    Returns:
        ``{"path", "validation"}`` (the problems name the file, as ``shown_as`` when given, and the
        lines of the file as written).

    Raises:
        FileRefused: the file cannot be written.
    """
    validation = validate_draft(draft, shown_as or target.name, location)
    text = validation.text
    if validation.net is not None:
        text = dump_net(validation.net, draft_layout(draft))
        # the problems (placement only: the net loads) at the lines of the file as written
        validation = validate_text(text, shown_as or target.name, draft, location)
    if target.suffix.lower() != ".toml":
        if validation.net is None:
            raise FileRefused(f"{target.name}: a draft with problems can only be saved as .toml")
        from coordinator.netfile.pnml import dump_pnml

        text = dump_pnml(validation.net, draft_layout(draft))
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(target, text)
    except OSError as exc:
        raise FileRefused(f"{target.name}: cannot write: {exc.strerror or exc}") from None
    return {"path": str(target), "validation": validation.to_json()}


def export_draft(draft: dict[str, Any], fmt: str, *, hidden: bool = True) -> tuple[str, str]:
    """Convert a draft: ``(text, media type)`` for ``fmt`` ``toml``, ``pnml`` or ``dot``.

    Raises:
        FileRefused: the draft has problems (PNML and DOT need a net), or an unknown format.
    """
    validation = validate_draft(draft)
    if fmt == "toml":
        text = dump_net(validation.net, draft_layout(draft)) if validation.net is not None else validation.text
        return text, "application/toml"
    if validation.net is None:
        raise FileRefused("the drawing has problems: fix them before exporting it as " + fmt.upper())
    if fmt == "pnml":
        from coordinator.netfile.pnml import dump_pnml

        return dump_pnml(validation.net, draft_layout(draft)), "application/xml"
    if fmt == "dot":
        from coordinator.netfile.dot import to_dot

        return to_dot(validation.net, show_hidden=hidden), "text/vnd.graphviz"
    raise FileRefused(f"unknown export format {fmt!r}: use toml, pnml or dot")
