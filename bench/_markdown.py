"""Write a benchmark's results into docs/*.md: one '## ' section, replaced in place or appended."""
from __future__ import annotations

from pathlib import Path


def replace_section(path: Path, section: str) -> None:
    """Put ``section`` (its first line is its '## ' heading) into the Markdown file ``path``.

    The section whose heading line is the same line is replaced, up to the next '## ' heading;
    a section not there yet is appended. Other sections are kept as they are.
    """
    path = Path(path)
    heading = section.lstrip().splitlines()[0].rstrip()
    text = path.read_text() if path.exists() else f"# {path.stem.title()}\n"
    lines = text.splitlines(keepends=True)
    start = next((i for i, ln in enumerate(lines) if ln.rstrip() == heading), None)
    body = section.strip() + "\n"
    if start is None:
        path.write_text(text.rstrip("\n") + "\n\n" + body)
        return
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    rest = "".join(lines[end:])
    path.write_text("".join(lines[:start]) + body + ("\n" + rest if rest else ""))


def publish(section: str, write: str | None) -> None:
    """A report's ``report`` command: print the section and, with ``--write FILE``, put it in
    FILE in place of the section of the same heading."""
    if write:
        replace_section(Path(write), section)
    print(section)
