"""Streaming: chunk-by-chunk parsing, profiling and gating equal the whole-file results."""
from __future__ import annotations

import gzip

import numpy as np
import pytest

from gatesopt import GcodeError, parse
from gatesopt import _scan
from gatesopt.energy import profile
from gatesopt.parse import DEFAULT_FEED_MM_S
from gatesopt.stream import gate_stream, iter_chunks, profile_stream

from conftest import PROJECT_INSTANCES, SHARED_INSTANCES


def test_chunks_end_at_line_boundaries_and_cover_the_file(tmp_path):
    text = "".join(f"G1 X{i} Y{i % 7} F600 ; line {i}\n" for i in range(5000)) + "G1 X0"
    p = tmp_path / "a.gcode.gz"
    p.write_bytes(gzip.compress(text.encode()))
    pieces = list(iter_chunks(p, chunk_bytes=4096))
    assert len(pieces) > 10
    assert b"".join(c for c, _ in pieces) == text.encode()
    assert all(c.endswith(b"\n") for c, _ in pieces[:-1])
    assert [l0 for _, l0 in pieces] == list(np.cumsum([0] + [c.count(b"\n") for c, _ in pieces[:-1]]))


def test_carried_state_gives_the_whole_file_rows():
    text = ("G20\nM83\nG91\nG1 X1 E0.1 F60\nG90\nG92 X0\nM82\nG1 X2 E5\nG92 E0\nM106 S128\n"
            "S0 Y\nG1 Y3 E1\nM104 S200\nG1 X0 E2\n")
    whole = parse(text)
    lines = text.splitlines(keepends=True)
    state = _scan.initial_state(25.0, DEFAULT_FEED_MM_S)
    parts = []
    for a, b in ((0, 4), (4, 9), (9, 14)):
        parts.append(parse("".join(lines[a:b]), state=state, line_offset=a, require_moves=False))
    end = np.vstack([p.end_mm for p in parts if p.n_steps])
    assert np.allclose(end, whole.end_mm)
    assert np.array_equal(np.concatenate([p.enabled for p in parts if p.n_steps]), whole.enabled)
    assert np.allclose(np.concatenate([p.fan for p in parts if p.n_steps]), whole.fan)


def test_error_line_numbers_count_from_the_whole_file(tmp_path):
    p = tmp_path / "bad.gcode"
    p.write_text("".join("G1 X1 F600\n" for _ in range(3000)) + "G1 X1.2.3\n")
    with pytest.raises(GcodeError, match=r"bad.gcode:3001: G1 X1.2.3: bad number for X"):
        profile_stream(p, chunk_bytes=2048)


def test_a_warning_found_in_every_chunk_is_given_once(tmp_path):
    """A BFB file (M101/M103 switch the extruder) is read in 4 KB chunks: every chunk finds M101
    again, the user reads it once, at the file's first M101 line."""
    layer = "M101\nG1 X10 Y10 F900\nG1 X20 Y10\nM103\n"
    text = "G28\nG1 Z0.3 F900\n" + "".join(f"G1 Z{0.3 + 0.2 * i:.2f}\n{layer}" for i in range(600))
    p = tmp_path / "bfb.gcode"
    p.write_text(text)
    assert len(list(iter_chunks(p, chunk_bytes=4096))) > 5
    r = profile_stream(p, chunk_bytes=4096)
    m101 = [w for w in r.warnings if "M101" in w]
    assert m101 == [w for w in parse(text, source=str(p)).warnings if "M101" in w]
    assert len(m101) == 1 and f"{p}:4: M101" in m101[0]


@pytest.mark.parametrize("name", ["real_prusa261_benchy.gcode.gz", "slic3r13_star_honey20.gcode.gz",
                                  "real_fullcontrol_ripple_vase.gcode.gz"])
@pytest.mark.parametrize("chunk", [60_000, 1_000_000])
def test_streamed_profile_equals_the_whole_file(name, chunk):
    path = SHARED_INSTANCES / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    # the whole file's report as `gatesopt profile --time-model paper` gives it: the stalls of
    # the file's own motor lines in its printer's firmware counted
    from gatesopt.energy import load_profile
    from gatesopt.rewrite.figures import profile_report
    from gatesopt.rewrite.printer import file_firmware
    whole = parse(path)
    r = profile_report(whole, load_profile("paper"), "paper", "paper", file_firmware(whole)[1])[0]
    s = profile_stream(path, chunk_bytes=chunk)
    assert s.n_lines == r.n_lines and s.n_steps == r.n_steps and s.n_layers == r.n_layers
    assert s.energy_j == pytest.approx(r.energy_j, rel=1e-12)
    assert s.time_s == pytest.approx(r.time_s, rel=1e-12)
    assert np.allclose(s.layer_energy_j, r.layer_energy_j, rtol=1e-9, atol=1e-9)
    for k in r.sectors_j:
        assert s.sectors_j[k] == pytest.approx(r.sectors_j[k], rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("name", ["real_prusa261_benchy.gcode.gz", "real_orca230_arcs.gcode.gz",
                                  "real_cura591.gcode.gz"])
def test_limits_read_in_pieces_are_the_whole_files(name):
    """The planner limits of a file read in pieces (its settings from head and tail, each piece's
    limit lines from their lines on) are the whole file's at every step: PrusaSlicer and
    OrcaSlicer write their config block (machine limits, flavor, printer) at the end and switch
    M204 per feature, which a middle chunk alone does not have."""
    from gatesopt.limits import PieceLimits, machine_limits
    from gatesopt.stream import _head_and_tail
    path = SHARED_INSTANCES / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    whole = parse(path)
    want = machine_limits(whole)
    text = path.read_bytes()
    text = gzip.decompress(text) if name.endswith(".gz") else text
    cut = text.index(b"\n", len(text) // 2) + 1
    state = _scan.initial_state(25.0, DEFAULT_FEED_MM_S)
    first = parse(text[:cut], source=name, state=state, require_moves=False)
    second = parse(text[cut:], source=name, state=state, require_moves=False,
                   line_offset=first.n_lines)
    pieces = PieceLimits.of_settings(parse(_head_and_tail(path), require_moves=False))
    lim1, pieces = pieces.of_piece(first)
    lim2, _ = pieces.of_piece(second)
    assert (lim1.firmware, lim1.junction, lim1.profile) == (want.firmware, want.junction,
                                                              want.profile)
    got = np.vstack([lim1.per_step(first), lim2.per_step(second)])
    assert len(got) == whole.n_steps
    assert np.array_equal(got, want.per_step(whole), equal_nan=True)


@pytest.mark.parametrize("name", ["real_prusa261_benchy.gcode.gz", "real_orca230_arcs.gcode.gz"])
def test_streamed_planner_time_is_the_whole_files(name):
    """``gatesopt profile --stream``'s planner time (the default report) within 0.05 % of the
    whole file's (each chunk planned on its own: the look-ahead restarts at a boundary); before
    the limits were read from the file's ends, a 1 MB chunk read 3.0-3.2 % more on these files
    (the first chunk's limits everywhere)."""
    path = SHARED_INSTANCES / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    from gatesopt.energy import load_profile
    from gatesopt.rewrite.figures import profile_report
    whole = parse(path)
    want = profile_report(whole, load_profile("paper"), "planner", "paper")[0]
    s = profile_stream(path, chunk_bytes=1_000_000, time_model="planner", energy_time_model="paper")
    assert s.time_s == pytest.approx(want.time_s, rel=5e-4)
    assert s.energy_j == pytest.approx(want.energy_j, rel=1e-12)


def test_streamed_gating_gives_the_input_warnings_once(tmp_path):
    """A slicer placeholder left in every layer (``M204 S{accel}``): gate_stream reports it, once,
    at its first line, as parse and profile_stream do (it used to report no warning at all)."""
    lines = (PROJECT_INSTANCES / "cyl_grid.gcode").read_text().splitlines(keepends=True)
    text = "".join(ln + ("M204 S{accel}\n" if ln.startswith(";Z:") else "") for ln in lines)
    src = tmp_path / "ph.gcode"
    src.write_text(text)
    res = gate_stream(src, tmp_path / "out.gcode", chunk_bytes=8_000)
    assert res.chunks > 2 and res.verified
    first = next(i for i, ln in enumerate(text.splitlines()) if ln.startswith("M204")) + 1
    placeholder = [w for w in res.warnings if "placeholder" in w]
    n = text.count("M204 S{accel}")
    assert placeholder == [f"{src}:{first}: M204 S{{accel}}: unexpanded slicer placeholder ignored "
                           f"(as the firmware ignores a word without a value) ({n - 1} more M204 lines "
                           "like it)"]
    assert placeholder[0] in parse(text, source=str(src)).warnings


def test_streamed_gating_is_verified_and_close_to_whole_file(tmp_path):
    from gatesopt.gating import GatingOptions, build
    from gatesopt.gating.solve import solve
    src = PROJECT_INSTANCES / "cyl_grid.gcode"
    out = tmp_path / "out.gcode"
    res = gate_stream(src, out, chunk_bytes=8_000)
    assert res.chunks > 2 and res.verified
    whole = solve(build(parse(src), GatingOptions(rotate="none")), "dp")
    # keeping motors on at chunk boundaries can only cost energy, and only a little
    assert whole.energy_j <= res.energy_after_j + 1e-6 < res.energy_before_j
    assert res.energy_after_j <= whole.energy_j * 1.01
    assert profile(parse(out)).n_lines == res.lines_after
    # never overwrite without force, and nothing partial is left behind
    with pytest.raises(Exception, match="exists"):
        gate_stream(src, out, chunk_bytes=8_000)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.gcode"]


def _x_pairs_between_y_moves(n: int = 120) -> str:
    """Y moves of 1 s (X idle) between two X moves of 0.02 s each: two of X's idle intervals in a
    row are 0.04 s apart, less than the klipper-gating module's 0.1 s between two changes of a pin
    (its rule B), so only every other one may be off, across chunk boundaries too."""
    out = ["G21", "G90", "M83", "G28", "G1 Z0.2 F600", ";LAYER:0", "G1 X10 Y10 F6000"]
    x = 10.0
    for k in range(n):
        out.append(f"G1 Y{60 if k % 2 == 0 else 10} E2 F3000")
        for _ in range(2):
            x += 0.5
            out.append(f"G1 X{x:.1f} E0.02 F1500")
    out.append("G1 X0 Y200 F6000")
    return "\n".join(out) + "\n"


def _x_pairs_between_short_y_moves(n: int = 200) -> str:
    """Y moves of 0.04 s (X idle) between pairs of X moves of 0.02 s: two of X's idle intervals in
    a row have their offs (and their ons) 0.08 s apart, less than the module's 0.1 s between a
    change of a pin and the change two back (its rule B with two queued changes), so only every
    other one may be off; where a chunk ends between the two X moves the first interval of the
    next chunk is 0.08 s after the last one of the chunk before."""
    out = ["G21", "G90", "M83", "G28", "G1 Z0.2 F600", ";LAYER:0", "G1 X10 Y10 F6000"]
    x = 10.0
    for k in range(n):
        out.append(f"G1 Y{12 if k % 2 == 0 else 10} E0.1 F3000")
        for _ in range(2):
            x += 0.5
            out.append(f"G1 X{x:.1f} E0.02 F1500")
    out.append("G1 X0 Y200 F6000")
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("slots", [1, 2])
@pytest.mark.parametrize("shaped", [False, True])
def test_streamed_klipper_gating_is_what_the_module_gates_across_chunks(tmp_path, shaped, slots):
    """gate_stream with --firmware klipper-gating: the module sees the whole file, so its rule B
    counts from a gated interval in the chunk before; every line of the streamed output is one the
    module gates (the whole output read as the module reads it), with and without an input
    shaper's window (``printer``), at several chunk sizes, with one change of a pin in flight and
    with two queued (``pin_queue_slots``, each with a file where its rule B binds)."""
    from gatesopt.printer_config import read_printer_config
    from gatesopt.verify import verify
    from gatesopt.verify.schedule import scheduled_lines
    src = tmp_path / "pairs.gcode"
    src.write_text(_x_pairs_between_y_moves() if slots == 1 else _x_pairs_between_short_y_moves())
    cfg = tmp_path / "printer.cfg"
    cfg.write_text("[printer]\nkinematics: cartesian\nmax_velocity: 300\nmax_accel: 3000\n"
                   + ("[input_shaper]\nshaper_type: mzv\nshaper_freq_x: 30\nshaper_freq_y: 30\n" if shaped else "")
                   + f"[gatesopt_gating]\npin_queue_slots: {slots}\n")
    printer = read_printer_config(cfg)
    original = parse(src)
    for chunk in (300, 333, 450, 700):
        out = tmp_path / f"out{chunk}.gcode"
        kw = {"printer": printer} if printer is not None else {}
        res = gate_stream(src, out, firmware="klipper-gating", chunk_bytes=chunk, **kw)
        assert res.chunks > 10 and res.verified and res.energy_after_j < res.energy_before_j
        output = parse(out)
        rep = verify(original, output, firmware="klipper-gating", printer=printer)
        assert rep.ok, [str(f) for f in rep.findings[:3]]
        lines = scheduled_lines(output, firmware="klipper-gating", start_ahead_s=0.0018, end_late_s=0.001,
                                printer=printer, original=original)
        assert len(lines) > 30 and all(s.gated for s in lines)

