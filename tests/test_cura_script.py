"""The Cura post-processing script, run the way Cura runs it: execute(data) over per-layer chunks."""
from __future__ import annotations

import importlib
import json
import shutil
import sys
from pathlib import Path

import pytest

from gatesopt import parse
from gatesopt.verify import verify

from conftest import REPO, SHARED_INSTANCES, read_bytes

SCRIPT = REPO / "integrations" / "cura" / "GatesOpt.py"


@pytest.fixture
def cura_script(tmp_path, monkeypatch):
    """Cura's layout: PostProcessingPlugin/Script.py and PostProcessingPlugin/scripts/GatesOpt.py."""
    pkg = tmp_path / "PostProcessingPlugin"
    (pkg / "scripts").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "scripts" / "__init__.py").write_text("")
    (pkg / "Script.py").write_text(
        "class Script:\n"
        "    def __init__(self):\n        self.settings = {}\n"
        "    def getSettingValueByKey(self, key):\n        return self.settings.get(key)\n")
    shutil.copy(SCRIPT, pkg / "scripts" / "GatesOpt.py")
    monkeypatch.syspath_prepend(str(tmp_path))
    for m in [m for m in sys.modules if m.startswith("PostProcessingPlugin")]:
        del sys.modules[m]
    mod = importlib.import_module("PostProcessingPlugin.scripts.GatesOpt")
    script = mod.GatesOpt()
    gatesopt_exe = shutil.which("gatesopt") or str(Path(sys.executable).with_name("gatesopt"))
    script.settings = {"formulation": "dp", "firmware": "marlin", "motors": "X,Y", "max_added_time_pct": 1.0,
                       "reorder": False, "rotate": False, "time_limit": 20.0, "command": gatesopt_exe}
    return mod, script


def cura_chunks(text: str) -> list[str]:
    """Split G-code the way Cura hands it to scripts: a header chunk, then one chunk per ;LAYER:."""
    lines = text.splitlines(keepends=True)
    cuts = [0] + [i for i, ln in enumerate(lines) if ln.startswith(";LAYER:")] + [len(lines)]
    return ["".join(lines[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]


def test_setting_data_is_valid_json(cura_script):
    _, script = cura_script
    d = json.loads(script.getSettingDataString())
    assert d["key"] == "GatesOpt" and "formulation" in d["settings"]


def test_split_like_keeps_cura_chunks(cura_script):
    mod, _ = cura_script
    chunks = [";FLAVOR:Marlin\nM104\n", ";LAYER:0\nG1 X1\n", "", ";LAYER:1\nG1 X2\n"]
    out = "".join(chunks).replace("G1 X1\n", "G1 X0.5\nM18 Y\nG1 X1\n")
    got = mod.split_like(out, chunks)
    assert len(got) == 4 and got[2] == "" and got[1].startswith(";LAYER:0") and "M18 Y" in got[1]
    assert "".join(got) == out


def test_execute_on_real_cura_output(cura_script):
    mod, script = cura_script
    path = SHARED_INSTANCES / "cura413_star_triangles20.gcode.gz"
    if not path.exists():
        pytest.skip(f"{path} not found")
    text = read_bytes(path).decode()
    data = cura_chunks(text)
    out = script.execute(list(data))
    assert len(out) == len(data)
    for a, b in zip(data[1:], out[1:]):
        assert b.splitlines()[0] == a.splitlines()[0]        # every layer chunk still starts with its ;LAYER:
    result = "".join(out)
    assert result != text and "M18" in result
    rep = verify(parse(text), parse(result), firmware="marlin")
    assert rep.ok, rep.findings[:3]


def test_execute_skips_postprocessed_and_keeps_data_on_failure(cura_script):
    mod, script = cura_script
    data = [";FLAVOR:Marlin\n;POSTPROCESSED\n", ";LAYER:0\nG1 X1 F600\n"]
    assert script.execute(list(data)) == data
    broken = [";FLAVOR:Marlin\n", ";LAYER:0\nG1 X1.2.3\n"]
    warnings = []
    script._warn = warnings.append
    assert script.execute(list(broken)) == broken
    assert warnings and "bad number for X" in warnings[0]
