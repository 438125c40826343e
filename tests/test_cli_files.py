"""Paths and failures of the command line (issue 37): an argument that is no file is "no such
file" (never G-code text), ``-`` reads standard input in every command that reads a file, every
failure is one line ``gatesopt: error: ...`` with exit code 2 (never a traceback), ``.gz`` outputs
are gzipped, and nothing of the user's is overwritten without ``--force``."""
from __future__ import annotations

import gzip
import os
import io
import json
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gatesopt import parse
from gatesopt.cli import build_parser, main

from conftest import PROJECT_INSTANCES

SRC = PROJECT_INSTANCES / "square_lines.gcode"
TINY = ("G28\nG90\nM82\nG92 E0\nG1 Z0.2 F600\nG1 X10 Y10 F3000\nG1 X20 Y10 E1 F1200\n"
        "G1 X20 Y20 E2\nG1 X10 Y20 E3\nG1 X10 Y10 E4\nG1 Z0.4\nG1 X20 Y10 E5\nG1 X20 Y20 E6\n")


class _Stdin(io.TextIOWrapper):
    """Standard input holding ``data`` (text and ``.buffer``)."""

    def __init__(self, data: bytes):
        super().__init__(io.BytesIO(data), encoding="utf-8")


def run_cli(argv, capsys, monkeypatch, stdin: bytes = b""):
    """(exit code, stdout, stderr) of ``gatesopt ARGV``, in this process."""
    monkeypatch.setattr(sys, "stdin", _Stdin(stdin))
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def one_error_line(err: str) -> str:
    """The one line of a failure: ``gatesopt: error: ...`` and nothing else but warnings."""
    lines = [ln for ln in err.splitlines() if not ln.startswith("gatesopt: warning:")]
    assert len(lines) == 1 and lines[0].startswith("gatesopt: error: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    return lines[0]


@pytest.mark.parametrize("argv", [["profile", "benchy"], ["solve", "my_print.gcod", "-o", "x.gcode"],
                                  ["order", "benchy", "-o", "x.gcode"], ["verify", "benchy", "SRC"],
                                  ["compare", "benchy"], ["batch", "benchy", "--out", "r.csv"],
                                  ["calibrate", "--gcode", "benchy", "--power-log", "SRC", "-o", "p.toml"],
                                  ["report", "benchy", "-o", "r.html"]])
def test_a_name_that_is_no_file_is_no_such_file(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(SRC) if a == "SRC" else a for a in argv]
    rc, out, err = run_cli(argv, capsys, monkeypatch)
    name = argv[1] if argv[0] != "calibrate" else "benchy"
    assert rc == 2 and one_error_line(err).startswith(f"gatesopt: error: {name}: no such ")
    assert sorted(p.name for p in tmp_path.iterdir()) == []          # nothing written


def test_the_library_reads_a_name_as_a_file_and_text_only_when_asked():
    from gatesopt import GcodeError, parse_text
    with pytest.raises(GcodeError, match=r"^benchy: no such file$"):
        parse("benchy")
    with pytest.raises(GcodeError, match=r"no such file \(G-code text given as one line: use gatesopt.parse_text\)"):
        parse("G1 X10 Y10 F600")
    assert parse_text("G1 X10 Y10 F600").n_steps == 1
    assert parse("G1 X10 Y10 F600\n").n_steps == 1         # text with a line break is text


def test_the_survey_tracebacks_are_one_line(tmp_path, capsys, monkeypatch):
    folder = tmp_path / "SOME_DIR"
    folder.mkdir()
    rc, _, err = run_cli(["solve", SRC, "-o", folder, "--force", "--no-order"], capsys, monkeypatch)
    assert rc == 2 and one_error_line(err) == f"gatesopt: error: {folder}: is a directory; give a file name"
    assert folder.is_dir() and not any(folder.iterdir())
    rc, _, err = run_cli(["report", SRC, "-o", tmp_path / "r.html"], capsys, monkeypatch)
    assert rc == 2 and "not a results file of gatesopt batch" in one_error_line(err)
    assert not (tmp_path / "r.html").exists()
    # a bad option: one line too, not argparse's usage text
    rc, _, err = run_cli(["solve", SRC, "-o", tmp_path / "x.gcode", "--firmware", "nope"], capsys, monkeypatch)
    assert rc == 2 and one_error_line(err).startswith("gatesopt: error: solve: argument --firmware: invalid choice")


def test_a_gz_output_is_gzipped_and_reads_back(tmp_path, capsys, monkeypatch):
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}.gcode.gz"
        rc, _, err = run_cli(["solve", SRC, "-o", out, "--rotate", "none", "--no-order", "--threads", "1"],
                             capsys, monkeypatch)
        assert rc == 0, err
        outs.append(out.read_bytes())
    assert outs[0][:2] == b"\x1f\x8b" and outs[0] == outs[1]        # no time stamp: same bytes
    assert gzip.decompress(outs[0]).startswith(SRC.read_bytes()[:20])
    rc, out, _ = run_cli(["verify", SRC, tmp_path / "out0.gcode.gz"], capsys, monkeypatch)
    assert rc == 0 and "all checks hold" in out
    rc, _, err = run_cli(["order", SRC, "-o", tmp_path / "o.gcode.gz"], capsys, monkeypatch)
    assert rc == 0, err
    assert (tmp_path / "o.gcode.gz").read_bytes()[:2] == b"\x1f\x8b"


def test_every_command_that_reads_a_file_reads_standard_input(tmp_path, capsys, monkeypatch):
    src = SRC.read_bytes()
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_cli(["profile", "-"], capsys, monkeypatch, src)
    assert rc == 0 and out.startswith("file        <stdin>"), err
    rc, out, err = run_cli(["order", "-", "-o", "o.gcode"], capsys, monkeypatch, src)
    assert rc == 0 and "verified      yes" in out, err
    rc, out, err = run_cli(["order", "-", "-o", "-"], capsys, monkeypatch, src)       # G-code on stdout
    assert rc == 0 and parse(out.encode()).n_steps > 0 and "verified      yes" in err
    rc, out, err = run_cli(["verify", "-", "o.gcode"], capsys, monkeypatch, src)
    assert rc == 0 and "all checks hold" in out, err
    rc, out, err = run_cli(["compare", "-", "--formulations", "greedy"], capsys, monkeypatch, src)
    assert rc == 0 and "<stdin>" in out, err
    rc, out, err = run_cli(["solve", "-", "-o", "s.gcode", "--no-order", "--rotate", "none"], capsys,
                           monkeypatch, src)
    assert rc == 0, err
    rc, out, err = run_cli(["batch", "-", "--out", "b.json", "--no-order", "--rotate", "none"], capsys,
                           monkeypatch, src)
    assert rc == 0 and "1 rows: 1 verified" in out, err
    rows = json.loads((tmp_path / "b.json").read_text())
    rc, out, err = run_cli(["report", "-", "-o", "r.html"], capsys, monkeypatch,
                           json.dumps(rows).encode())
    assert rc == 0 and (tmp_path / "r.html").exists(), err
    # a power log on standard input, the G-code from a file
    from gatesopt.calibrate import synthesize_log, write_power_log
    from test_calibrate import PRINT, truth
    (tmp_path / "print.gcode").write_text(PRINT)
    write_power_log(synthesize_log(parse(PRINT + "\n"), truth(), noise_w=0.3, offset_s=12.0), tmp_path / "log.csv")
    rc, out, err = run_cli(["calibrate", "--gcode", "print.gcode", "--power-log", "-", "-o", "p.toml",
                            "--time-model", "paper"], capsys, monkeypatch, (tmp_path / "log.csv").read_bytes())
    assert rc == 0 and "energy error" in out and (tmp_path / "p.toml").exists(), err
    rc, out, err = run_cli(["calibrate", "--gcode", "-", "--power-log", "log.csv", "-o", "p2.toml",
                            "--time-model", "paper"], capsys, monkeypatch, PRINT.encode())
    assert rc == 0 and (tmp_path / "p2.toml").exists(), err
    # standard input is read once
    rc, _, err = run_cli(["verify", "-", "-"], capsys, monkeypatch, src)
    assert rc == 2 and "standard input (-) can be read only once" in one_error_line(err)


def test_nothing_of_the_users_is_overwritten(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "in").mkdir()
    g = tmp_path / "in" / "a.gcode"
    g.write_bytes(SRC.read_bytes())
    before = g.read_bytes()
    # batch --write-dir onto the inputs' own folder would replace them
    rc, _, err = run_cli(["batch", "in", "--out", "r.csv", "--write-dir", "in", "--force", "--no-order"],
                         capsys, monkeypatch)
    assert rc == 2 and "is an input file" in one_error_line(err) and g.read_bytes() == before
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "a.gcode").write_text("mine")
    rc, _, err = run_cli(["batch", "in", "--out", "r.csv", "--write-dir", "w", "--no-order"], capsys, monkeypatch)
    assert rc == 2 and "exists; pass --force" in one_error_line(err)
    assert (tmp_path / "w" / "a.gcode").read_text() == "mine" and not (tmp_path / "r.csv").exists()
    # a report over its own results file, or over PNGs already there
    rc, _, err = run_cli(["batch", "in", "--out", "r.csv", "--no-order", "--rotate", "none"], capsys, monkeypatch)
    assert rc == 0, err
    results = (tmp_path / "r.csv").read_bytes()
    rc, _, err = run_cli(["report", "r.csv", "-o", "r.csv", "--force"], capsys, monkeypatch)
    assert rc == 2 and "must not be the input" in one_error_line(err) and (tmp_path / "r.csv").read_bytes() == results
    rc, _, err = run_cli(["report", "r.csv", "-o", "r.html", "--png", "figs"], capsys, monkeypatch)
    assert rc == 0, err
    png = sorted((tmp_path / "figs").iterdir())[0]
    png.write_bytes(b"mine")
    rc, _, err = run_cli(["report", "r.csv", "-o", "r2.html", "--png", "figs"], capsys, monkeypatch)
    assert rc == 2 and "exists; pass --force" in one_error_line(err)
    assert png.read_bytes() == b"mine" and not (tmp_path / "r2.html").exists()


# ------------------------------------------------------------------------------------------------
# the CLI's arguments, fuzzed: whatever the values, a run ends in a result or in one error line
ODD_VALUES = ["", "-", "0", "-1", "nan", "inf", "1e400", "abc", "X,Y,Q", "0x0", "missing.gcode", "DIR",
              "TEXT", "GCODE", "CSV", "JSON", "out.gcode.gz", "out.png"]
#: sensible values by the option's metavar (most draws), so that runs get past the first check
GOOD_VALUES = {"S": ["1", "0.5"], "P": ["1", "5"], "N": ["1", "2"], "X,Y": ["X,Y", "X", "X,Y,E"],
               "auto|none|DEG": ["auto", "none", "45"], "WxD": ["220x220", "50x50"],
               "NAME|TOML": ["paper", "component_example"], "OUT.gcode": ["out.gcode", "-", "out.gcode.gz"],
               "OUT.png": ["out.png"], "REPORT.json": ["r.json"], "REPORT.html": ["r.html"],
               "DIR": ["figs"], "GCODE": ["GCODE"], "PROFILE.toml": ["p.toml"], "LIST": ["greedy", "dp"],
               "RESULTS.csv|RESULTS.json": ["r.csv", "r.json"], "F[,F...]": ["dp", "greedy,dp"],
               "OUT.json": ["o.json"], "ADDRESS": ["local"]}


def _value(token: str, tmp) -> str:
    return {"DIR": str(tmp / "dir"), "TEXT": str(tmp / "notes.txt"), "GCODE": str(tmp / "tiny.gcode"),
            "CSV": str(tmp / "rows.csv"), "JSON": str(tmp / "rows.json")}.get(token, token)


def _actions(command: str):
    parser = build_parser(command)
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return [a for a in sub._actions if a.dest != "help"]


@st.composite
def command_lines(draw):
    command = draw(st.sampled_from(["profile", "solve", "order", "verify", "compare", "batch", "report",
                                    "calibrate"]))
    argv = [command]
    for a in _actions(command):
        if a.dest == "dask":
            continue                                   # would start a cluster
        if not a.option_strings:                       # positionals: a file
            good = "CSV" if command == "report" else "GCODE"
            argv.append(draw(st.sampled_from([good, good, good, "-", "missing.gcode", "DIR", "TEXT"])))
        elif a.required or a.dest == "output" or draw(st.integers(0, 3)) == 0:
            flag = a.option_strings[-1]
            if a.nargs == 0:
                argv.append(flag)
                continue
            odd = draw(st.integers(0, 7)) == 0
            if a.choices:
                pool = ["bogus"] if odd else list(a.choices)
            else:
                pool = ODD_VALUES if odd or a.metavar not in GOOD_VALUES else GOOD_VALUES[a.metavar]
            argv += [flag, str(draw(st.sampled_from(pool)))]
    return argv


@settings(max_examples=int(os.environ.get("GATESOPT_FUZZ_EXAMPLES", 80)), deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(argv=command_lines())
def test_fuzzed_command_lines_end_in_a_result_or_one_error_line(argv, tmp_path_factory, capsys, monkeypatch):
    tmp = tmp_path_factory.mktemp("fuzz")
    (tmp / "dir").mkdir()
    (tmp / "notes.txt").write_text("not g-code at all\n")
    (tmp / "tiny.gcode").write_text(TINY)
    (tmp / "rows.csv").write_text("file,formulation,verified,saving_pct\nx.gcode,dp,True,12.5\n")
    (tmp / "rows.json").write_text('[{"file": "x.gcode", "formulation": "dp", "verified": true}]')
    monkeypatch.chdir(tmp)
    argv = [_value(t, tmp) for t in argv]
    flags = {f for a in _actions(argv[0]) for f in a.option_strings}
    for flag, quick in (("--order-budget", "1"), ("--budget", "1"), ("--time-limit", "2")):
        if flag in flags and flag not in argv:
            argv += [flag, quick]
    rc, out, err = run_cli(argv, capsys, monkeypatch, TINY.encode())
    import os
    if os.environ.get("FUZZLOG"):
        with open(os.environ["FUZZLOG"], "a") as f:
            f.write(f"{rc}\t{' '.join(argv)}\t{err.strip().splitlines()[-1] if err.strip() else ''}\n")
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    if rc == 2:
        one_error_line(err)
    else:
        assert rc in (0, 1), (argv, rc, err)


def test_batch_takes_the_ordering_options_of_solve(tmp_path, capsys, monkeypatch):
    """``batch --order-mode free --budget S`` reaches every file's run, as in ``solve``."""
    import gatesopt.batch as batch_mod
    seen = []
    real = batch_mod.process_file

    def recording(path, options, data=None):
        seen.append((options.order_mode, options.budget_s))
        return real(path, options, data)

    monkeypatch.setattr(batch_mod, "process_file", recording)
    out = tmp_path / "r.csv"
    rc, _, err = run_cli(["batch", SRC, "--out", out, "--order-mode", "free", "--budget", "3"],
                         capsys, monkeypatch)
    assert rc == 0, err
    assert seen == [("free", 3.0)]
    rc, _, err = run_cli(["batch", SRC, "--out", out, "--order-mode", "sideways"], capsys, monkeypatch)
    assert rc == 2 and "--order-mode" in one_error_line(err)

