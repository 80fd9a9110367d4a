"""Benchmark tables in docs/benchmarks.md: each benchmark owns the text between `<!-- bench:NAME -->` and
`<!-- /bench:NAME -->`, opened by a line that names the command that made it and the date.

By default a benchmark rewrites its section only when both markers are in the file (`--docs` also appends a missing
section, `--no-docs` never writes). An absent file is never an error: the tables are still printed and in the JSON.
"""
from __future__ import annotations

import datetime
from pathlib import Path

from odometry.shared.atomic_io import atomic_write_text
from vslam.paths import REPO_ROOT

DOCS_FILE = REPO_ROOT / "docs" / "benchmarks.md"


def markers(name: str) -> tuple[str, str]:
    """The opening and closing marker of benchmark `name`'s section."""
    return f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"


def section_body(markdown: str, command: str, date: datetime.date | None = None) -> str:
    """What goes between the markers: the provenance line, then the tables."""
    day = (date or datetime.date.today()).isoformat()
    return f"Made by `{command}` on {day}.\n\n{markdown.strip()}\n"


def find_section(text: str, name: str) -> tuple[int, int] | None:
    """(start, end) of the text between the markers of `name`, or None when either is missing or out of order."""
    begin, end = markers(name)
    i = text.find(begin)
    j = text.find(end, i + len(begin)) if i >= 0 else -1
    return None if i < 0 or j < 0 else (i + len(begin), j)


def replace_section(text: str, name: str, body: str, append: bool = False) -> str | None:
    """`text` with the section of `name` holding `body`; a missing section is appended when `append`, else None."""
    span = find_section(text, name)
    if span is None:
        if not append:
            return None
        begin, end = markers(name)
        return text.rstrip("\n") + ("\n\n" if text.strip() else "") + f"{begin}\n{body}{end}\n"
    start, stop = span
    return text[:start] + "\n" + body + text[stop:]


def publish(name: str, markdown: str | None, command: str, docs: bool | None = None,
            path: str | Path | None = None, date: datetime.date | None = None) -> str | None:
    """Write benchmark `name`'s tables into its section of the docs file (default docs/benchmarks.md).

    docs=None: only when the section's markers exist; True: also append a missing section; False: never.
    Returns a line for the user (what was written, or why not when it was asked for), or None.
    """
    path = Path(path) if path is not None else DOCS_FILE
    if docs is False or markdown is None:
        return None
    if not path.is_file():
        return f"docs: {path} not found; tables not written there" if docs else None
    text = path.read_text(encoding="utf-8")
    new = replace_section(text, name, section_body(markdown, command, date), append=bool(docs))
    if new is None:
        return None
    atomic_write_text(path, new)
    return f"docs: wrote the {name} tables into {path}"
