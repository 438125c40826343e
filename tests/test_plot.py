"""gatesopt.plot: the Fig. 4 / Fig. 5 PNG, its power timeline, and bad output paths."""
from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gatesopt import energy, parse
from gatesopt.energy import SECTORS, EnergyReport
from gatesopt.errors import GatesoptError
from gatesopt.plot import HEIGHT_PX, WIDTH_PX, PlotError, plot_profile, power_timeline

INSTANCES = Path(__file__).resolve().parents[1] / "instances"


def _report(duration_s, power_w, name="hand.gcode") -> EnergyReport:
    """An EnergyReport from hand-made per-step durations and powers."""
    dur = np.asarray(duration_s, float)
    e = dur * np.asarray(power_w, float)
    sectors = dict.fromkeys(SECTORS, 0.0)
    sectors.update(X=0.3 * e.sum(), Y=0.2 * e.sum(), heater=0.4 * e.sum(), idle=0.1 * e.sum())
    return EnergyReport(
        source=name, profile="hand", n_lines=len(dur), n_steps=len(dur), n_moves=len(dur),
        n_layers=1, time_s=float(dur.sum()), energy_j=float(e.sum()), sectors_j=sectors,
        by_kind_j={}, by_kind_s={}, layer_time_s=np.array([dur.sum()]),
        layer_energy_j=np.array([e.sum()]), layer_z_mm=np.array([0.2]), step_energy_j=e,
        step_end_s=np.cumsum(dur))


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_power_timeline_per_step_when_few_steps():
    # 2 s at 10 W, a zero-time step (no energy), 3 s at 40 W
    edges, p = power_timeline(_report([2.0, 0.0, 3.0], [10.0, 99.0, 40.0]), bins=10)
    np.testing.assert_allclose(edges, [0.0, 2.0, 5.0])
    np.testing.assert_allclose(p, [10.0, 40.0])


def test_power_timeline_bins_keep_the_energy():
    # 5 s at 10 W, 5 s at 20 W, 10 s at 30 W in 2 bins of 10 s: means 15 W and 30 W
    edges, p = power_timeline(_report([5.0, 5.0, 10.0], [10.0, 20.0, 30.0]), bins=2)
    np.testing.assert_allclose(edges, [0.0, 10.0, 20.0])
    np.testing.assert_allclose(p, [15.0, 30.0])
    rng = np.random.default_rng(1)
    rep = _report(rng.exponential(0.2, 5000), rng.uniform(2, 40, 5000))
    edges, p = power_timeline(rep, bins=2000)
    assert len(p) == 2000
    assert np.sum(p * np.diff(edges)) == pytest.approx(rep.energy_j, rel=1e-9)
    assert p.min() >= 2 - 1e-9 and p.max() <= 40 + 1e-9


def test_png_is_written_with_the_expected_size(tmp_path):
    prog = parse(INSTANCES / "square_lines.gcode")
    out = plot_profile(energy.profile(prog), tmp_path / "profile.png")
    assert out == tmp_path / "profile.png"
    assert out.stat().st_size > 20_000           # two drawn panels, not an empty canvas
    assert _png_size(out) == (WIDTH_PX, HEIGHT_PX)


def test_binned_png_for_many_steps(tmp_path):
    rng = np.random.default_rng(0)
    out = plot_profile(_report(rng.exponential(0.1, 20_000), rng.uniform(5, 40, 20_000)),
                       tmp_path / "big.PNG", bins=500)
    assert _png_size(out) == (WIDTH_PX, HEIGHT_PX)


@pytest.mark.parametrize("bad, words", [
    ("profile.jpg", "ending in .png"),
    ("no/such/folder/profile.png", "does not exist"),
    (".", "ending in .png"),
    ("dir.png", "is a directory"),
])
def test_bad_path_is_refused_with_a_clear_error(tmp_path, bad, words):
    (tmp_path / "dir.png").mkdir()
    rep = _report([1.0], [10.0])
    with pytest.raises(PlotError) as err:
        plot_profile(rep, tmp_path / bad)
    assert isinstance(err.value, GatesoptError)
    assert words in str(err.value) and "\n" not in str(err.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.png"]     # nothing written


def test_report_without_time_is_refused(tmp_path):
    with pytest.raises(PlotError, match="nothing to plot"):
        plot_profile(_report([0.0], [10.0]), tmp_path / "p.png")


def test_importing_gatesopt_does_not_import_matplotlib():
    code = "import sys, gatesopt, gatesopt.plot; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_profile_does_not_overwrite_a_plot_without_force(tmp_path, capsys):
    from gatesopt.cli import main
    target = tmp_path / "p.png"
    target.write_bytes(b"the user's picture")
    argv = ["profile", str(INSTANCES / "square_lines.gcode"), "--plot", str(target)]
    assert main(argv) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert target.read_bytes() == b"the user's picture"
    assert main(argv + ["--force"]) == 0
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
