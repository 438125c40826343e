"""Safe mode's labelled objects (ordering/blocks.py, ``object_runs``): a plate of objects labelled
as PrusaSlicer, M486, Klipper's exclude_object and Cura label them is re-ordered object by object,
each object's moves inside its own labels, the label lines of every layer kept, the output
verified; an object that cannot move (a heater line inside it) keeps its place and says why."""
from __future__ import annotations

import re

import numpy as np
import pytest

import gatesopt
from gatesopt import slicers
from gatesopt.ordering import OrderingOptions
from gatesopt.rewrite.order import order_program
from gatesopt.verify.ordering import check_objects

STYLES = ("prusa", "m486", "klipper", "cura")


def _labels(style: str, k: int) -> tuple[list[str], list[str]]:
    """(lines opening object k's moves, lines closing them) as each slicer writes them."""
    name = f"part{k}.stl id:{k} copy 0"
    if style == "prusa":
        return [f"; printing object {name}"], [f"; stop printing object {name}"]
    if style == "m486":
        return [f"; printing object {name}", f"M486 S{k}"], [f"; stop printing object {name}", "M486 S-1"]
    if style == "klipper":
        return [f"EXCLUDE_OBJECT_START NAME=part{k}"], [f"EXCLUDE_OBJECT_END NAME=part{k}"]
    return [f";MESH:part{k}.stl"], []


def object_plate(seed: int, style: str, *, n_layers: int = 3, n_objects: int = 6,
                 heater_in: int | None = None) -> str:
    """``n_objects`` square objects on a plate, each a wall loop then three infill lines per layer,
    printed in a random order per layer (a sure cut for the test), every travel between objects
    retracted. ``heater_in``: object with an ``M104`` between its wall and its infill."""
    rng = np.random.default_rng(seed)
    centres = [np.array([30.0 + 40.0 * (k % 3), 30.0 + 40.0 * (k // 3)]) for k in range(n_objects)]
    out = ["G21", "G90", "M83", "M104 S200", "G28", "M204 P1000 T1500", "G1 Z0.2 F600"]
    if style == "m486":
        out.append(f"M486 T{n_objects}")
    if style == "klipper":
        out += [f"EXCLUDE_OBJECT_DEFINE NAME=part{k} CENTER={c[0]:g},{c[1]:g}" for k, c in enumerate(centres)]
    for layer in range(n_layers):
        z = 0.2 * (layer + 1)
        out += [";LAYER_CHANGE", f"G1 Z{z:.2f} F720"]
        order = rng.permutation(n_objects).tolist()
        for k in order:
            c = centres[k]
            ring = c + np.array([[-8, -8], [8, -8], [8, 8], [-8, 8], [-8, -8]], float)
            opens, closes = _labels(style, k)
            if style == "cura":
                out += ["G1 E-0.8 F2100"] + opens + [f"G0 X{ring[0][0]:.3f} Y{ring[0][1]:.3f} F9000"]
            else:
                out += opens + ["G1 E-0.8 F2100", f"G1 X{ring[0][0]:.3f} Y{ring[0][1]:.3f} F9000"]
            out += ["G1 E0.8 F2100", ";TYPE:Perimeter"]
            out += [f"G1 X{p[0]:.3f} Y{p[1]:.3f} E0.5 F1800" for p in ring[1:]]
            if k == heater_in:
                out.append("M104 S205")
            for y in (-4.0, 0.0, 4.0):
                a, b = c + [-7.0, y], c + [7.0, y]
                out += [f"G1 X{a[0]:.3f} Y{a[1]:.3f} F9000", ";TYPE:Internal infill",
                        f"G1 X{b[0]:.3f} Y{b[1]:.3f} E0.4 F3000"]
            out += closes
        if style == "cura":
            out += ["G1 E-0.8 F2100", ";MESH:NONMESH"]
    out.append("M104 S0")
    return "\n".join(out) + "\n"


def _objects_per_layer(text: str) -> list[list[tuple[str, float]]]:
    """Per layer (``;LAYER_CHANGE``), the objects in print order with the filament extruded inside
    each one's labels, read line by line from the text (independent of ``gatesopt``): an
    extrusion's object is the one the last label line before it opened."""
    layers: list[list] = []
    current = None
    for line in text.splitlines():
        s = line.strip()
        if s == ";LAYER_CHANGE":
            layers.append([])
            continue
        m = re.fullmatch(r"(?:; printing object|EXCLUDE_OBJECT_START NAME=|;MESH:)\s*(part\d+)\S*.*", s)
        if m:
            current = m.group(1)
            continue
        if re.fullmatch(r"; stop printing object.*|EXCLUDE_OBJECT_END.*|;MESH:NONMESH", s):
            current = None
            continue
        e = re.search(r"\bE([-\d.]+)", s)
        if layers and s.startswith("G1") and ("X" in s or "Y" in s) and e and float(e.group(1)) > 0:
            row = layers[-1]
            if not row or row[-1][0] != current:
                row.append([current, 0.0])
            row[-1][1] += float(e.group(1))
    return [[(k, round(v, 6)) for k, v in row] for row in layers]


def _label_lines(text: str) -> list[str]:
    return [ln.strip() for ln in text.splitlines() if slicers.object_label(ln) is not None]


@pytest.mark.parametrize("style", STYLES)
def test_objects_reorder_in_safe_mode_inside_their_labels(style):
    prog = gatesopt.parse(object_plate(1, style))
    off = order_program(prog, OrderingOptions(mode="safe", blocks=False), time_limit_s=1.0)
    on = order_program(prog, OrderingOptions(mode="safe"), time_limit_s=1.0)
    assert on.ok, on.findings[:3]
    rep = on.problem.block_report
    assert rep["object_runs"] == 2 and rep["object_runs_moved"] >= 1     # layers 1 and 2
    # the objects' order is what moved: the print is faster than with objects as barriers
    assert on.summary["print_time_after_s"] < off.summary["print_time_after_s"]
    assert on.summary["travel_after_mm"] < 0.9 * on.summary["travel_before_mm"]
    before, after = _objects_per_layer(prog.data.decode()), _objects_per_layer(on.text)
    assert len(before) == len(after) == 3
    for b, a in zip(before, after):
        # every object printed once per layer, inside its own labels, with all its filament
        assert all(k is not None for k, _ in a)
        assert sorted(a) == sorted(b)
        assert a[0] == b[0]                     # the first object keeps the layer's entry
    assert any(a != b for a, b in zip(before, after))
    # the same label lines, as many per layer
    assert sorted(_label_lines(on.text)) == sorted(_label_lines(prog.data.decode()))
    assert not check_objects(prog, on.output)


def test_an_object_with_a_heater_line_inside_stays_a_barrier():
    prog = gatesopt.parse(object_plate(2, "prusa", n_objects=7, heater_in=3))
    res = order_program(prog, OrderingOptions(mode="safe"), time_limit_s=1.0)
    assert res.ok, res.findings[:3]
    kept = res.problem.block_report["objects_kept"]
    assert kept["barrier"][0] == 2                  # object 3 in layers 1 and 2
    assert any("kept in place as barriers: a barrier line inside the object" in n for n in res.problem.notes)
    before, after = _objects_per_layer(prog.data.decode()), _objects_per_layer(res.text)
    for b, a in zip(before, after):
        names_b, names_a = [k for k, _ in b], [k for k, _ in a]
        i = names_b.index("part3")
        # it keeps its place, and no object crossed it
        assert names_a.index("part3") == i
        assert sorted(names_a[:i]) == sorted(names_b[:i])
    assert _label_lines(res.text).count("M104 S205") == 0     # (not a label)
    assert res.text.count("M104 S205") == prog.data.decode().count("M104 S205")


def test_objects_check_finds_moves_outside_their_labels():
    text = object_plate(3, "prusa", n_layers=2)
    prog = gatesopt.parse(text)
    # the last object's opening label written after its first extrusion: that move is now
    # outside any object's labels
    lines = text.splitlines()
    opens = [i for i, ln in enumerate(lines) if ln.startswith("; printing object")]
    k = opens[-1]
    label = lines.pop(k)
    first_e = next(i for i in range(k, len(lines)) if " E0.5" in lines[i])
    lines.insert(first_e + 1, label)
    bad = gatesopt.parse("\n".join(lines) + "\n")
    found = check_objects(prog, bad)
    assert found and found[0].check == "objects"
    assert not check_objects(prog, prog)


@pytest.mark.parametrize("row", slicers.OBJECT_LABELS, ids=lambda r: f"{r.family}-{r.kind}")
def test_each_object_label_row_reads_its_example(row):
    got = slicers.object_label(row.example)
    assert got is not None and got[0] is row
    assert row.word in row.example.lower().encode()



def test_free_mode_keeps_objects_in_place():
    # free mode's groups choose their own entry, which the block order does not see: objects stay
    prog = gatesopt.parse(object_plate(4, "m486"))
    res = order_program(prog, OrderingOptions(mode="free"), time_limit_s=1.0)
    assert res.ok, res.findings[:3]
    assert not res.problem.block_report.get("object_runs_moved")
    before, after = _objects_per_layer(prog.data.decode()), _objects_per_layer(res.text)
    assert [[k for k, _ in a] for a in after] == [[k for k, _ in b] for b in before]
