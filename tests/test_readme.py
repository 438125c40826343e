"""The README's library example runs as written (on a bundled instance instead of print.gcode)."""
from __future__ import annotations

import re
from conftest import PROJECT_INSTANCES, REPO as ROOT


def test_the_library_example_runs(capsys):
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## Library\s+```python\n(.*?)```", text, re.S).group(1)
    assert "ordering.solve" in block and "gating.solve" in block
    code = block.replace('"print.gcode"', repr(str(PROJECT_INSTANCES / "star_lines_m82.gcode")))
    exec(compile(code, "README.md (## Library)", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == "[0 2 1] [False False  True]"     # the polyline example's order
