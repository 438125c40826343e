"""A parse warning repeated on many lines is one line with a count and its first line; one on
another command is its own line (realsweep P13). Before: a Bambu Studio file's one ``M970.3`` line
with a letter given twice and its 128 base64 ``M624`` lines were said as one line, "M970.3 ...
(128 more lines like it)": the M624 lines were hidden under a line they are not like."""
from __future__ import annotations

from gatesopt.parse import parse_text
from gatesopt.stream import profile_stream

from conftest import PROJECT_INSTANCES

BASE = (PROJECT_INSTANCES / "square_grid_m82.gcode").read_text()


def _bambu_text(n_m624: int = 40) -> tuple[str, int, int]:
    lines = BASE.splitlines(keepends=True)
    head = "M970.3 Q0 A7 B30 C90 Q0 H15 K0\n"
    text = head + "".join(ln + (f"M624 A{'QAg'[k % 3]}AAAAAAAAA=\n" if k % 5 == 0 and k // 5 < n_m624 else "")
                          for k, ln in enumerate(lines))
    first_m624 = next(i for i, ln in enumerate(text.splitlines()) if ln.startswith("M624")) + 1
    return text, first_m624, text.count("\nM624 ")


def test_each_command_once_with_its_count_and_first_line():
    text, first, n = _bambu_text()
    w = [s for s in parse_text(text, source="b.gcode").warnings if "given twice" in s]
    assert w == [
        "b.gcode:1: M970.3 Q0 A7 B30 C90 Q0 H15 K0: a letter given twice: Marlin and Klipper take "
        "the last value, and so does gatesopt",
        f"b.gcode:{first}: {text.splitlines()[first - 1]}: a letter given twice: Marlin and Klipper "
        f"take the last value, and so does gatesopt ({n - 1} more M624 lines like it)"]


def test_placeholders_are_one_line_per_command():
    text = BASE.replace("G1 Z", "M204 S{accel}\nG1 Z")
    n = text.count("M204 S{accel}")
    w = [s for s in parse_text(text, source="p.gcode").warnings if "placeholder" in s]
    assert len(w) == 1 and w[0].endswith(f"({n - 1} more M204 lines like it)") and n > 5


def test_a_streamed_file_says_what_the_whole_file_says(tmp_path):
    """Read in chunks, each chunk finds the warnings again: counted over the chunks, the lines are
    the whole file's."""
    text, _, _ = _bambu_text()
    src = tmp_path / "b.gcode"
    src.write_text(text)
    streamed = profile_stream(src, chunk_bytes=4_000).warnings
    whole = parse_text(text, source=str(src)).warnings
    assert [s for s in streamed if "given twice" in s] == [s for s in whole if "given twice" in s]
