"""`gatesopt batch` and `gatesopt report`: rows for every file, errors as rows, pool == Dask, HTML figures."""
from __future__ import annotations

import csv
import shutil
import subprocess
from pathlib import Path

import pytest

from gatesopt.batch import COLUMNS, TIMING_COLUMNS, BatchOptions, read_rows, run_batch
from gatesopt.cli import main
from gatesopt.report import build_figures, write_report

from conftest import PROJECT_INSTANCES

SMALL = ["square_lines.gcode", "star_triangles.gcode"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("batch")
    out = []
    for name in SMALL:
        src = PROJECT_INSTANCES / name
        if not src.exists():
            pytest.skip(f"{src} missing: run instances/make_instances.py")
        shutil.copy(src, d / name)
        out.append(str(d / name))
    bad = d / "broken.gcode"
    bad.write_text("G1 X0 F600\nG1 X1.2.3\n")
    out.append(str(bad))
    return out


def _stable(rows):
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS and k != "output"} for r in rows]


OPTS = BatchOptions(formulation="dp", time_limit_s=20.0, rotate="none", order=False)


def test_batch_rows_errors_and_resume(files, tmp_path):
    out = tmp_path / "r.csv"
    rows = run_batch(files, OPTS, out=out, jobs=1, progress=False)
    assert [Path(r["file"]).name for r in rows] == [Path(f).name for f in files]
    good, bad = rows[:2], rows[2]
    assert all(r["verified"] and not r["error"] for r in good), [r["error"] or r["findings"] for r in good]
    assert all(float(r["energy_after_j"]) <= float(r["energy_before_j"]) for r in good)
    assert bad["error"].endswith("broken.gcode:2: G1 X1.2.3: bad number for X") and not bad["verified"]
    with open(out, newline="") as f:
        assert tuple(csv.DictReader(f).fieldnames) == COLUMNS
    # resume: nothing left to do, the same rows come back
    again = run_batch(files, OPTS, out=out, jobs=1, resume=True, progress=False)
    assert len(again) == 3 and len(read_rows(out)) == 3


def test_process_pool_and_dask_give_identical_rows(files):
    pytest.importorskip("distributed")
    pool = run_batch(files, OPTS, jobs=2, progress=False)
    dask = run_batch(files, OPTS, jobs=2, dask="local", progress=False)
    assert _stable(pool) == _stable(dask)


def test_outputs_written_only_when_verified(files, tmp_path):
    opts = BatchOptions(formulation="dp", rotate="none", order=False, write_dir=str(tmp_path / "out"))
    rows = run_batch(files, opts, progress=False)
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == sorted(Path(r["file"]).name for r in rows if r["verified"])
    assert "broken.gcode" not in written


def test_batch_cli_refuses_to_overwrite(files, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["batch", *files[:1], "--out", str(out), "--quiet", "--rotate", "none", "--no-order"]) == 0
    assert main(["batch", *files[:1], "--out", str(out), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_report_has_every_figure_and_renders_in_chromium(files, tmp_path):
    rows = run_batch(files[:2], OPTS, progress=False, formulations=("greedy", "dp"))
    figs = build_figures(rows)
    names = [f[0] for f in figs]
    for expected in ("Energy saving per file", "Saving by infill pattern", "File size increase",
                     "Greedy vs exact"):
        assert expected in names
    html_path = tmp_path / "report.html"
    pngs = write_report(rows, html_path, png_dir=tmp_path / "png")
    assert len(pngs) == len(figs) and all(Path(p).stat().st_size > 1000 for p in pngs)
    text = html_path.read_text()
    assert text.count("data:image/png;base64,") == len(figs)
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if not chromium:
        pytest.skip("Chromium not installed (apt-get install chromium): browser rendering not checked")
    dom = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                          "--no-first-run", "--disable-background-networking", "--disable-component-update",
                          "--disable-sync", f"--user-data-dir={tmp_path / 'chrome'}",
                          "--virtual-time-budget=5000", "--dump-dom", html_path.as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    assert f'data-figures-rendered="{len(figs)}/{len(figs)}"' in dom


def test_report_to_a_missing_folder_is_a_one_line_error(files, tmp_path, capsys):
    rows_path = tmp_path / "r.csv"
    run_batch(files[:1], OPTS, out=rows_path, progress=False)
    assert main(["report", str(rows_path), "-o", str(tmp_path / "nope" / "r.html")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_largest_files_go_first_with_several_workers(tmp_path):
    # a large file started last would be the only one still running (the 2-job batch bench fell
    # to 1.69x the 1-job throughput once the work per file got shorter)
    import gzip
    from gatesopt.batch import largest_first, text_size
    small, mid, big = tmp_path / "small.gcode", tmp_path / "mid.gcode.gz", tmp_path / "big.gcode"
    small.write_text("G1 X1\n" * 10)
    mid.write_bytes(gzip.compress(b"G1 X1\n" * 1000))        # small on disk, 6000 bytes of text
    big.write_text("G1 X1\n" * 500)
    assert text_size(mid) == 6000 and mid.stat().st_size < big.stat().st_size
    work = [(str(small), "a"), (str(big), "b"), (str(mid), "c")]
    assert [w[1] for w in largest_first(work)] == ["c", "b", "a"]
    assert text_size(tmp_path / "missing.gcode") == 0
