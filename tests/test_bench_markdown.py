"""bench/_markdown.py: every benchmark writes its docs section through this one helper."""
from __future__ import annotations

import sys

from conftest import REPO

sys.path.insert(0, str(REPO / "bench"))
from _markdown import replace_section  # noqa: E402

DOC = ("# Results\n\nintro\n\n## Curve ordering\n\nold ordering\n\n"
       "## Curve ordering: peers (LKH-3)\n\nold peers\n\n## Power gating\n\ngating\n")


def test_replaces_only_the_section_with_the_same_heading_line(tmp_path):
    p = tmp_path / "RESULTS.md"
    p.write_text(DOC)
    replace_section(p, "## Curve ordering\n\nnew ordering\n")
    assert p.read_text() == DOC.replace("old ordering", "new ordering")
    replace_section(p, "## Curve ordering: peers (LKH-3)\n\nnew peers")
    assert "new peers" in p.read_text() and "old peers" not in p.read_text()
    assert p.read_text().count("## ") == 3 and p.read_text().endswith("## Power gating\n\ngating\n")


def test_appends_a_new_section_and_creates_a_missing_file(tmp_path):
    p = tmp_path / "RESULTS.md"
    p.write_text(DOC)
    replace_section(p, "## Huge files\n\nnumbers")
    assert p.read_text() == DOC + "\n## Huge files\n\nnumbers\n"
    q = tmp_path / "BENCHMARKS.md"
    replace_section(q, "## Batch throughput\n\nx")
    assert q.read_text() == "# Benchmarks\n\n## Batch throughput\n\nx\n"
    replace_section(q, "## Batch throughput\n\ny")              # idempotent in shape
    assert q.read_text() == "# Benchmarks\n\n## Batch throughput\n\ny\n"


def test_a_hand_written_block_survives_a_rewrite_of_its_section(tmp_path):
    from _markdown import KEEP_CLOSE, KEEP_OPEN
    p = tmp_path / "BENCHMARKS.md"
    note = f"{KEEP_OPEN}\nIn this run the largest file took 1.5 s.\n{KEEP_CLOSE}"
    p.write_text(DOC.replace("old ordering", "old table\n\n" + note))
    replace_section(p, "## Curve ordering\n\nnew table\n")
    text = p.read_text()
    assert "old table" not in text and "new table" in text
    assert text.count(note) == 1 and text.index("new table") < text.index(note) < text.index("## Curve ordering: peers")
    # a section that brings its own block replaces the old one
    replace_section(p, f"## Curve ordering\n\nnewer\n\n{KEEP_OPEN}\nnew note\n{KEEP_CLOSE}\n")
    assert "largest file took" not in p.read_text() and "new note" in p.read_text()
