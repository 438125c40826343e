"""``gatesopt order --plot``: one layer's travels before and after, and every layer's travel,
read from the two files with the report's definition of travel."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from gatesopt import parse
from gatesopt.cli import main
from gatesopt.ordering.travel_stats import travel_stats
from gatesopt.rewrite import order_program
from gatesopt.ordering.plot import (HEIGHT_PX, WIDTH_PX, default_layer, layer_segments,
                                    plot_ordering, travel_per_layer_mm)
from gatesopt.plot import PlotError

from conftest import PROJECT_INSTANCES

STAR = PROJECT_INSTANCES / "star_triangles.gcode"


@pytest.fixture(scope="module")
def ordered():
    program = parse(STAR)
    return program, order_program(program, formulation="greedy", workers=1)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_travel_per_layer_adds_up_to_the_reports_travel(ordered):
    program, res = ordered
    for prog, key in ((program, "travel_before_mm"), (res.output, "travel_after_mm")):
        per_layer = travel_per_layer_mm(prog)
        assert per_layer.shape == (prog.n_layers,)
        assert per_layer.sum() == pytest.approx(res.summary[key], rel=1e-12)
        assert per_layer.sum() == pytest.approx(travel_stats(prog)["travel_mm"], rel=1e-12)


def test_a_layers_travel_segments_are_its_travel(ordered):
    program, res = ordered
    per_layer = travel_per_layer_mm(res.output)
    for layer in range(res.output.n_layers):
        ext, trv = layer_segments(res.output, layer)
        assert ext.shape[1:] == (2, 2) and trv.shape[1:] == (2, 2)
        # no arcs in this file: the chords are the moves
        assert np.linalg.norm(trv[:, 1] - trv[:, 0], axis=1).sum() == pytest.approx(per_layer[layer])
    # the same extrusions in both files, layer by layer (a re-ordering moves none)
    for layer in range(program.n_layers):
        assert len(layer_segments(program, layer)[0]) == len(layer_segments(res.output, layer)[0])


def test_the_default_layer_is_the_one_cut_most():
    assert default_layer(np.array([5.0, 9.0, 7.0]), np.array([4.0, 2.0, 6.0])) == 1
    # nothing cut: the layer with the most travel
    assert default_layer(np.array([5.0, 9.0, 7.0]), np.array([5.0, 9.0, 7.0])) == 1
    assert default_layer(np.array([5.0, 3.0]), np.array([6.0, 3.5])) == 0


def test_plot_ordering_writes_a_png(ordered, tmp_path):
    program, res = ordered
    out = plot_ordering(program, res.output, tmp_path / "o.png", layer=3)
    assert _png_size(out) == (WIDTH_PX, HEIGHT_PX)


def test_plot_ordering_refuses_a_missing_layer_and_unrelated_files(ordered, tmp_path):
    program, res = ordered
    with pytest.raises(PlotError, match="layer 99 does not exist"):
        plot_ordering(program, res.output, tmp_path / "o.png", layer=99)
    other = parse(";LAYER:0\nG1 Z0.2\nG1 X1 Y1\nG1 X5 Y1 E1\nG1 X9 Y9\nG1 X9 Y5 E1\n")
    assert other.n_layers != program.n_layers
    with pytest.raises(PlotError, match="not a re-ordering"):
        plot_ordering(program, other, tmp_path / "o.png")
    with pytest.raises(PlotError, match="PNG"):
        plot_ordering(program, res.output, tmp_path / "o.jpg")
    assert not list(tmp_path.iterdir())


def test_cli_order_plot(tmp_path, capsys):
    out, png = tmp_path / "o.gcode", tmp_path / "o.png"
    assert main(["order", str(STAR), "-o", str(out), "--formulation", "greedy", "--workers", "1",
                 "--plot", str(png), "--plot-layer", "4"]) == 0
    assert _png_size(png) == (WIDTH_PX, HEIGHT_PX)
    assert f"plot          {png}" in capsys.readouterr().out
    # an existing plot is not overwritten without --force, and nothing else is written either
    out2 = tmp_path / "o2.gcode"
    assert main(["order", str(STAR), "-o", str(out2), "--plot", str(png)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err and not out2.exists()


@pytest.mark.parametrize("args, message", [
    (["--plot-layer", "2"], "--plot-layer needs --plot"),
    (["--plot", "{tmp}/p.png", "--plot-layer", "10"], "--plot-layer 10: layers are 0 to 9"),
    (["--plot", "{tmp}/p.svg"], "the plot is written as PNG"),
    (["--plot", "{tmp}/o.gcode"], "-o and --plot must name different files"),
    (["--plot", "{tmp}/j.png", "--json", "{tmp}/j.png"], "--json and --plot must name different files"),
    (["--json", "{tmp}/o.gcode"], "-o and --json must name different files"),
])
def test_cli_order_plot_refuses_bad_arguments_before_solving(tmp_path, capsys, args, message):
    out = tmp_path / "o.gcode"
    argv = ["order", str(STAR), "-o", str(out)] + [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
