"""Write a benchmark's results into docs/*.md: one '## ' section, replaced in place or appended."""
from __future__ import annotations

from pathlib import Path

#: a block a person wrote into a generated section (what a run showed, read by hand): kept, at
#: the end of the section, when a benchmark writes the section again without one of its own
KEEP_OPEN, KEEP_CLOSE = "<!-- hand-written -->", "<!-- /hand-written -->"


def _kept_block(text: str) -> str:
    a = text.find(KEEP_OPEN)
    b = text.find(KEEP_CLOSE, a + 1)
    return text[a:b + len(KEEP_CLOSE)] if a >= 0 and b > a else ""


def replace_section(path: Path, section: str) -> None:
    """Put ``section`` (its first line is its '## ' heading) into the Markdown file ``path``.

    The section whose heading line is the same line is replaced, up to the next '## ' heading;
    a section not there yet is appended. Other sections are kept as they are. A block between
    ``KEEP_OPEN`` and ``KEEP_CLOSE`` in the old section is carried into the new one (at its end)
    unless the new one brings its own.
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
    kept = _kept_block("".join(lines[start:end]))
    if kept and not _kept_block(body):
        body = body.rstrip("\n") + "\n\n" + kept + "\n"
    rest = "".join(lines[end:])
    path.write_text("".join(lines[:start]) + body + ("\n" + rest if rest else ""))


def publish(section: str, write: str | None) -> None:
    """A report's ``report`` command: print the section and, with ``--write FILE``, put it in
    FILE in place of the section of the same heading."""
    if write:
        replace_section(Path(write), section)
    print(section)
