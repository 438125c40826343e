"""Generate the project's own small G-code instances (no slicer needed).

Layered toolpaths for the papers' test models: a square prism, a cylinder and a star prism
(Fleming et al., Section 4: "a square prism, a cylinder, a star-shaped prism"), each filled with
the four infill patterns of 3DGates Fig. 12 / Section 6.3: line, grid, triangle and concentric
("square-circle"). 3 shapes x 4 patterns = 12 files, written PrusaSlicer-style so that they read
like real slicer output: a config header, temperatures, ``;LAYER_CHANGE`` / ``;Z:`` / ``;HEIGHT:``
layer markers, ``;TYPE:`` feature markers, retraction on travel, part fan from layer 2.

Geometry (all with shapely, pure and deterministic):
- perimeters: 2 closed loops per layer, the outline offset inwards by w/2 and 3w/2 (mitre joins so
  corners stay sharp, as a slicer's polygon offset keeps them);
- infill region: the outline offset by 1.75 w (2 w minus PrusaSlicer's default 25 % infill/perimeter
  overlap); parallel line families are clipped to it (lines: one family per layer, alternating
  0/90 degrees; grid: 0 and 90; triangles: 0, 60 and 120, all through one lattice point so they
  form triangles); concentric = repeated inward offsets of the inner perimeter.
- line spacing = families x w / density, as PrusaSlicer does for a given fill density.

E per mm of path comes from the extrusion cross-section PrusaSlicer's Flow model uses for a
w x h bead (a rectangle with semicircular ends: (w - h) h + pi (h/2)^2) over the filament area.
Coordinates are rounded to 3 decimals, E to 5, and written without leading zeros (``E.03385``)
as PrusaSlicer does, so rounding is the only numeric effect and the output is byte-stable.

Run ``python instances/make_instances.py`` to regenerate every file into ``instances/``
(``--out DIR`` to write elsewhere; the test suite regenerates into a temp dir and compares bytes).
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from shapely import affinity
from shapely.geometry import LineString, MultiPolygon, Polygon
from shapely.geometry.polygon import orient

# --- printer and print settings (PrusaSlicer 2.5-like defaults, see ../shared/instances/README.md)
BED_SHAPE = "0x0,250x0,250x210,0x210"
BED_X_MM, BED_Y_MM = 250.0, 210.0
CENTER_MM = (125.0, 105.0)          # PrusaSlicer --center 125,105
SIZE_MM = 20.0                      # each object is 20 mm across
N_LAYERS = 10
LAYER_H_MM = 0.2
WIDTH_MM = 0.45                     # extrusion width, every feature
NOZZLE_MM = 0.4
FILAMENT_D_MM = 1.75
DENSITY = 0.20                      # infill density
INFILL_OVERLAP = 0.25               # PrusaSlicer infill_overlap default (fraction of width)
PERIMETER_MM_S = 40.0
INFILL_MM_S = 60.0
TRAVEL_MM_S = 150.0
RETRACT_MM = 0.8
RETRACT_MM_S = 35.0                 # F2100
RETRACT_BEFORE_TRAVEL_MM = 2.0      # PrusaSlicer retract_before_travel
ZHOP_MM = 0.4
HOTEND_C, BED_C = 215, 60
CYL_SEGMENTS = 36                   # 10 degree facets: chord error 0.04 mm at r = 10 mm
SEAM_TOWARD_MM = (CENTER_MM[0] + 100.0, CENTER_MM[1] + 100.0)   # "aligned" rear-right seam

# Flow: PrusaSlicer Flow::mm3_per_mm for a bead of width w and height h (rounded rectangle).
BEAD_AREA_MM2 = (WIDTH_MM - LAYER_H_MM) * LAYER_H_MM + math.pi * (LAYER_H_MM / 2) ** 2
FILAMENT_AREA_MM2 = math.pi * (FILAMENT_D_MM / 2) ** 2
E_PER_MM = BEAD_AREA_MM2 / FILAMENT_AREA_MM2


@dataclass(frozen=True)
class Variant:
    """One instance file: shape x infill pattern x how the G-code is written."""

    name: str
    shape: str          # "square" | "cyl" | "star"
    pattern: str        # "lines" | "grid" | "triangles" | "concentric"
    absolute_e: bool    # M82 (absolute E) instead of M83
    g92_per_layer: bool # "G92 E0" at every layer change
    zhop: bool          # lift Z by ZHOP_MM on retracted travels


# 3 shapes x 4 patterns; M82/M83, per-layer G92 E0 and z-hop vary across them so that every writing
# style a PrusaSlicer-family file uses appears at least twice.
VARIANTS = (
    Variant("square_lines", "square", "lines", False, True, False),
    Variant("square_grid_m82", "square", "grid", True, True, False),
    Variant("square_triangles_zhop", "square", "triangles", False, True, True),
    Variant("square_concentric_m82", "square", "concentric", True, True, False),
    Variant("cyl_lines_zhop", "cyl", "lines", False, True, True),
    Variant("cyl_grid", "cyl", "grid", False, True, False),
    Variant("cyl_triangles_m82", "cyl", "triangles", True, True, False),
    Variant("cyl_concentric", "cyl", "concentric", False, True, False),
    Variant("star_lines_m82", "star", "lines", True, False, False),   # absolute E, never reset
    Variant("star_grid_zhop", "star", "grid", False, True, True),
    Variant("star_triangles", "star", "triangles", False, True, False),
    Variant("star_concentric_m82", "star", "concentric", True, True, False),
)

FAMILIES = {"lines": 1, "grid": 2, "triangles": 3, "concentric": 1}
SHAPE_TEXT = {"square": "square prism 20 x 20 mm", "cyl": "cylinder 20 mm diameter",
              "star": "five-point star prism 20 mm across"}


# ------------------------------------------------------------------------------------------------
# Geometry
def outline(shape: str) -> Polygon:
    """The object's cross-section, centred on the bed, counter-clockwise."""
    cx, cy = CENTER_MM
    r = SIZE_MM / 2
    if shape == "square":
        pts = [(cx - r, cy - r), (cx + r, cy - r), (cx + r, cy + r), (cx - r, cy + r)]
    elif shape == "cyl":
        a = np.arange(CYL_SEGMENTS) * (2 * math.pi / CYL_SEGMENTS)
        pts = list(zip(cx + r * np.cos(a), cy + r * np.sin(a)))
    elif shape == "star":
        a = math.pi / 2 + np.arange(10) * (math.pi / 5)
        rad = np.where(np.arange(10) % 2 == 0, r, r / 2)
        pts = list(zip(cx + rad * np.cos(a), cy + rad * np.sin(a)))
    else:
        raise ValueError(f"unknown shape {shape!r}")
    return orient(Polygon(pts), 1.0)


def polygons(geom) -> list[Polygon]:
    """The non-empty polygons of an offset result, in a fixed order (by centroid)."""
    if geom.is_empty:
        return []
    parts = list(geom.geoms) if isinstance(geom, MultiPolygon) else [geom]
    parts = [orient(p, 1.0) for p in parts if isinstance(p, Polygon) and p.area > 1e-6]
    return sorted(parts, key=lambda p: (round(p.centroid.y, 3), round(p.centroid.x, 3)))


def inset(poly: Polygon, d_mm: float):
    """Inward offset with sharp (mitre) corners, as a slicer's polygon offset keeps them."""
    return poly.buffer(-d_mm, join_style="mitre", mitre_limit=10.0)


def ring_xy(poly: Polygon) -> np.ndarray:
    """Exterior vertices (open ring, CCW), rounded to the 3 decimals the G-code is written with."""
    xy = np.round(np.asarray(poly.exterior.coords)[:-1], 3)
    keep = np.any(xy != np.roll(xy, 1, axis=0), axis=1)
    return xy[keep]


def start_at(ring: np.ndarray, toward: tuple[float, float]) -> np.ndarray:
    """Rotate a closed ring to start at the vertex nearest ``toward`` (the seam), and close it."""
    d = np.hypot(ring[:, 0] - toward[0], ring[:, 1] - toward[1])
    i = int(np.argmin(np.round(d, 6)))
    r = np.roll(ring, -i, axis=0)
    return np.vstack([r, r[:1]])


def line_family(region: Polygon, angle_deg: float, spacing_mm: float) -> list[np.ndarray]:
    """Parallel lines at ``angle_deg`` through a lattice point at the centre, clipped to ``region``.

    Returned as 2-point segments in scan order, alternate ones reversed (a zig-zag), each
    (2, 2) rounded to 3 decimals.
    """
    cx, cy = CENTER_MM
    rot = affinity.rotate(region, -angle_deg, origin=(cx, cy))
    xmin, ymin, xmax, ymax = rot.bounds
    k0, k1 = math.ceil((ymin - cy) / spacing_mm), math.floor((ymax - cy) / spacing_mm)
    t = math.radians(angle_deg)
    c, s = math.cos(t), math.sin(t)
    segs = []
    for k in range(k0, k1 + 1):
        y = cy + k * spacing_mm
        cut = rot.intersection(LineString([(xmin - 1, y), (xmax + 1, y)]))
        pieces = getattr(cut, "geoms", [cut])
        xs = sorted((min(p.coords[0][0], p.coords[-1][0]), max(p.coords[0][0], p.coords[-1][0]))
                    for p in pieces if isinstance(p, LineString) and p.length >= WIDTH_MM)
        for x0, x1 in xs:
            seg = np.array([[x0, y], [x1, y]]) - (cx, cy)
            seg = seg @ np.array([[c, s], [-s, c]]) + (cx, cy)   # rotate back by +angle
            segs.append(np.round(seg, 3))
    return [seg if i % 2 == 0 else seg[::-1] for i, seg in enumerate(segs)]


def layer_paths(shape: str, pattern: str, layer: int) -> list[tuple[str, np.ndarray]]:
    """(feature, polyline) in print order for one layer: perimeters inside-out, then infill."""
    out = outline(shape)
    paths = []
    for feature, d in (("Perimeter", 1.5 * WIDTH_MM), ("External perimeter", 0.5 * WIDTH_MM)):
        for p in polygons(inset(out, d)):
            paths.append((feature, start_at(ring_xy(p), SEAM_TOWARD_MM)))
    spacing = FAMILIES[pattern] * WIDTH_MM / DENSITY
    if pattern == "concentric":
        pos = paths[-1][1][0]
        k = 1
        while True:
            loops = polygons(inset(out, 1.5 * WIDTH_MM + k * spacing))
            loops = [p for p in loops if p.length >= 4 * WIDTH_MM]
            if not loops:
                break
            for p in loops:   # start each loop where the nozzle is, as slicers do
                ring = start_at(ring_xy(p), tuple(pos))
                paths.append(("Internal infill", ring))
                pos = ring[0]
            k += 1
        return paths
    region = inset(out, (2.0 - INFILL_OVERLAP) * WIDTH_MM)
    angles = {"lines": [0.0 if layer % 2 == 0 else 90.0], "grid": [0.0, 90.0],
              "triangles": [0.0, 60.0, 120.0]}[pattern]
    for p in polygons(region):
        for a in angles:
            paths.extend(("Internal infill", seg) for seg in line_family(p, a, spacing))
    return paths


# ------------------------------------------------------------------------------------------------
# G-code writing
def fmt(v: float, decimals: int) -> str:
    """PrusaSlicer's number style: fixed decimals, trailing zeros and the leading zero dropped."""
    s = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
    if s.startswith("0."):
        s = s[1:]
    elif s.startswith("-0."):
        s = "-" + s[2:]
    return "0" if s in ("", "-0", "-") else s


class Writer:
    """Tracks the nozzle and writes moves in one file's modal state (M82 or M83)."""

    def __init__(self, v: Variant):
        self.v = v
        self.out: list[str] = []
        self.xy = np.array([0.0, 0.0])     # after G28
        self.z_mm = 0.0
        self.e_mm = 0.0                    # logical E (absolute mode only)
        self.feed_mm_s: float | None = None
        self.retracted = False
        self.feature = ""

    def emit(self, line: str) -> None:
        self.out.append(line)

    def _feed(self, feed_mm_s: float) -> str:
        if self.feed_mm_s == feed_mm_s:
            return ""
        self.feed_mm_s = feed_mm_s
        return f" F{feed_mm_s * 60:.0f}"

    def _e_word(self, de_mm: float) -> str:
        if self.v.absolute_e:
            self.e_mm += de_mm
            return f"E{fmt(self.e_mm, 5)}"
        return f"E{fmt(de_mm, 5)}"

    def retract(self) -> None:
        if not self.retracted:
            self.emit(f"G1 {self._e_word(-RETRACT_MM)}{self._feed(RETRACT_MM_S)}")
            self.retracted = True

    def unretract(self) -> None:
        if self.retracted:
            self.emit(f"G1 {self._e_word(RETRACT_MM)}{self._feed(RETRACT_MM_S)}")
            self.retracted = False

    def travel(self, xy: np.ndarray, force_retract: bool = False) -> None:
        dist = float(np.hypot(*(xy - self.xy)))
        if dist > 0:
            retract = force_retract or self.retracted or dist > RETRACT_BEFORE_TRAVEL_MM
            if retract:
                self.retract()
            hop = retract and self.v.zhop
            if hop:
                self.emit(f"G1 Z{fmt(self.z_mm + ZHOP_MM, 3)}{self._feed(TRAVEL_MM_S)}")
            self.emit(f"G1 X{fmt(xy[0], 3)} Y{fmt(xy[1], 3)}{self._feed(TRAVEL_MM_S)}")
            if hop:
                self.emit(f"G1 Z{fmt(self.z_mm, 3)}")
            self.xy = np.asarray(xy, dtype=float)
        self.unretract()

    def layer_change(self, layer: int) -> None:
        z = round((layer + 1) * LAYER_H_MM, 3)
        self.emit(";LAYER_CHANGE")
        self.emit(f";Z:{z:g}")
        self.emit(f";HEIGHT:{LAYER_H_MM:g}")
        if self.v.g92_per_layer:
            self.emit("G92 E0")
            self.e_mm = 0.0
        self.retract()           # PrusaSlicer retract_layer_change
        self.emit(f"G1 Z{fmt(z, 3)}{self._feed(TRAVEL_MM_S)}")
        self.z_mm = z
        if layer == 1:
            self.emit("M106 S255")   # part fan from layer 2 (disable_fan_first_layers = 1)

    def path(self, feature: str, xy: np.ndarray) -> None:
        self.travel(xy[0])
        if feature != self.feature:
            self.emit(f";TYPE:{feature}")
            self.emit(f";WIDTH:{WIDTH_MM:g}")
            self.feature = feature
        feed = INFILL_MM_S if feature == "Internal infill" else PERIMETER_MM_S
        f = self._feed(feed)
        if f:
            self.emit(f"G1{f}")
        for p in xy[1:]:
            d = float(np.hypot(*(p - self.xy)))
            if d == 0:
                continue
            self.emit(f"G1 X{fmt(p[0], 3)} Y{fmt(p[1], 3)} {self._e_word(d * E_PER_MM)}")
            self.xy = p


def header(v: Variant) -> list[str]:
    e_mode = "M82 ; use absolute distances for extrusion" if v.absolute_e else \
        "M83 ; use relative distances for extrusion"
    return [
        "; generated by gatesopt instances/make_instances.py",
        f"; instance = {v.name}: {SHAPE_TEXT[v.shape]}, {N_LAYERS} layers of {LAYER_H_MM} mm, "
        f"{v.pattern} infill {DENSITY:.0%}",
        "",
        f"; bed_shape = {BED_SHAPE}",
        "; gcode_flavor = marlin2",
        f"; nozzle_diameter = {NOZZLE_MM}",
        f"; filament_diameter = {FILAMENT_D_MM}",
        f"; layer_height = {LAYER_H_MM}",
        f"; extrusion_width = {WIDTH_MM}",
        f"; perimeters = 2",
        f"; fill_pattern = {v.pattern}",
        f"; fill_density = {DENSITY:.0%}",
        f"; perimeter_speed = {PERIMETER_MM_S:.0f}",
        f"; infill_speed = {INFILL_MM_S:.0f}",
        f"; travel_speed = {TRAVEL_MM_S:.0f}",
        f"; retract_length = {RETRACT_MM}",
        f"; retract_speed = {RETRACT_MM_S:.0f}",
        f"; retract_before_travel = {RETRACT_BEFORE_TRAVEL_MM:.0f}",
        f"; retract_lift = {ZHOP_MM if v.zhop else 0}",
        f"; use_relative_e_distances = {0 if v.absolute_e else 1}",
        f"; temperature = {HOTEND_C}",
        f"; bed_temperature = {BED_C}",
        "",
        "M201 X1000 Y1000 Z200 E5000 ; sets maximum accelerations, mm/sec^2",
        "M203 X200 Y200 Z12 E120 ; sets maximum feedrates, mm / sec",
        "M107",
        ";TYPE:Custom",
        f"M140 S{BED_C} ; set bed temp",
        f"M104 S{HOTEND_C} ; set extruder temp",
        f"M190 S{BED_C} ; wait for bed temp",
        f"M109 S{HOTEND_C} ; wait for extruder temp",
        "G28 ; home all axes",
        "G21 ; set units to millimeters",
        "G90 ; use absolute coordinates",
        e_mode,
        "G92 E0",
    ]


def footer(w: Writer) -> None:
    w.emit(";TYPE:Custom")
    w.retract()
    w.emit(f"G1 Z{fmt(w.z_mm + 10, 3)} F720 ; move print head up")
    w.emit("G1 X0 Y200 F3000 ; present print")
    w.emit("M107")
    w.emit("M104 S0 ; turn off temperature")
    w.emit("M140 S0 ; turn off heatbed")
    w.emit("M84 X Y E ; disable motors")


def gcode(v: Variant) -> str:
    """The whole file for one variant, as text with ``\\n`` line endings."""
    w = Writer(v)
    w.out.extend(header(v))
    for layer in range(N_LAYERS):
        w.layer_change(layer)
        for feature, xy in layer_paths(v.shape, v.pattern, layer):
            w.path(feature, xy)
    footer(w)
    return "\n".join(w.out) + "\n"


def write_all(out_dir: str | Path) -> list[Path]:
    """Write every variant to ``out_dir/<name>.gcode``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for v in VARIANTS:
        p = out / f"{v.name}.gcode"
        p.write_bytes(gcode(v).encode("ascii"))
        paths.append(p)
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent),
                    help="directory to write the .gcode files to (default: instances/)")
    args = ap.parse_args(argv)
    for p in write_all(args.out):
        print(f"{p}  {p.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
