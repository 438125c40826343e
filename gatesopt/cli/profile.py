"""``gatesopt profile FILE``: energy and time of a print under the instruction-level model."""
from __future__ import annotations

import json
import os
import sys

from ..energy import SECTORS, load_profile
from ..errors import GatesoptError
from ..planner import TIME_MODELS, comparable_total_s, slicer_estimate_s
from .files import check_input, check_new_file, print_warnings, read_program

NAME = "profile"
HELP = "energy and time of a G-code file (3DGates energy model)"
DESCRIPTION = ("Profile the energy and time of a G-code file (plain or .gz) with the 3DGates "
               "instruction-level energy model.")


def add_arguments(p) -> None:
    p.add_argument("file", help="G-code file (.gcode or .gcode.gz), or - for standard input")
    p.add_argument("--profile", default="paper", metavar="NAME|TOML",
                   help="energy profile: a shipped name (paper, component_example) or a TOML file "
                        "(default: paper, the 3DGates tables)")
    p.add_argument("--time-model", choices=TIME_MODELS, default="planner",
                   help="the time reported: planner (default; acceleration, junction speeds and the "
                        "machine limits the file sets: within a few %% of the slicers' estimates) "
                        "or paper (T = L/F, 3DGates Eq. 2: 20-27 %% under PrusaSlicer's)")
    p.add_argument("--energy-time-model", choices=TIME_MODELS, default="paper",
                   help="the durations the energy model integrates over: paper (default; T = L/F, "
                        "what the 3DGates power tables were fitted on and what `solve` and `verify` "
                        "report) or planner")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--per-layer", action="store_true", help="add a table by layer")
    p.add_argument("--plot", metavar="OUT.png",
                   help="write energy over time (the paper's Fig. 4) and the energy-sector chart (Fig. 5)")
    p.add_argument("--force", action="store_true", help="overwrite an existing plot file")
    p.add_argument("--stream", action="store_true",
                   help="read the file chunk by chunk in bounded memory (automatic above 256 MB); "
                        "no --plot, no per-step data")


STREAM_ABOVE_BYTES = 256 << 20     # whole-file arrays take ~8x the file: stream big files


def _wants_stream(args) -> bool:
    check_input(args.file)
    if args.file == "-":
        if args.stream:
            raise GatesoptError("--stream reads a file chunk by chunk: give a file, not -")
        return False
    return args.stream or os.path.getsize(args.file) > STREAM_ABOVE_BYTES


def run_stream(args) -> int:
    from ..stream import profile_stream
    if args.plot:
        raise GatesoptError("--plot needs the whole file in memory: drop --stream (or --plot)")
    report = profile_stream(args.file, args.profile, time_model=args.time_model,
                            energy_time_model=args.energy_time_model)
    print_warnings(report.warnings)
    if args.json:
        json.dump(_json(report, args), sys.stdout, indent=2)
        print()
        return 0
    print(format_report(report, args.time_model, args.energy_time_model))
    if args.per_layer:
        print()
        print(format_layers(report))
    return 0


def _json(report, args, program=None) -> dict:
    d = report.to_dict(per_layer=args.per_layer)
    d["time_model"] = args.time_model
    d["energy_time_model"] = args.energy_time_model
    if program is not None:
        d["slicer_estimate_s"] = slicer_estimate_s(program)
    return d


def run(args) -> int:
    if args.plot:
        check_new_file(args.plot, [] if args.file == "-" else [args.file], args.force, png=True)
    if _wants_stream(args):
        return run_stream(args)
    program = read_program(args.file)       # its warnings on stderr
    prof = load_profile(args.profile)
    from ..rewrite.figures import profile_report
    from ..rewrite.printer import NOT_GATED, file_firmware
    name, firmware = file_firmware(program)     # the name and detection `solve` and `verify` use
    report, duration_s = profile_report(program, prof, args.time_model, args.energy_time_model,
                                           firmware)
    if args.plot:
        from ..plot import plot_profile
        plot_profile(report, args.plot)
    if args.json:
        d = _json(report, args, program)
        d["firmware"] = name
        if args.time_model != "paper":
            d["paper_time_s"] = float(program.duration_s.sum())
        json.dump(d, sys.stdout, indent=2)
        print()
        return 0
    print(format_report(report, args.time_model, args.energy_time_model,
                        paper_time_s=None if args.time_model == "paper" else float(program.duration_s.sum())))
    if name == NOT_GATED:
        print(f"firmware    {name}: gatesopt gates nothing on this printer (see `solve`); none of "
              "the file's motor lines counted as a stall, as `solve` and `verify` count them")
    else:
        print(f"firmware    {name}: the stalls of the file's motor lines counted, as `solve` and "
              "`verify` count them")
    print(_slicer_line(program, duration_s, args.time_model))
    if args.per_layer:
        print()
        print(format_layers(report))
    if args.plot:
        print(f"\nplot written to {args.plot}")
    return 0


def _slicer_line(program, duration_s, time_model: str = "planner") -> str:
    """The slicer's own estimate beside ours (heat-up waits and homing left out: no slicer counts them)."""
    est = slicer_estimate_s(program)
    if est is None:
        return "slicer      no estimate in the file"
    ours = comparable_total_s(program, duration_s)
    return (f"slicer      {est:,.0f} s ({_hms(est)}) estimated by the slicer; ours ({time_model} model) "
            f"without heat-up and homing {ours:,.0f} s, {100 * (ours / est - 1):+.1f} %")


def _hms(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}h{s // 60 % 60:02d}m{s % 60:02d}s"


TIME_WORDS = {"planner": "planner model: acceleration, junction speeds",
              "paper": "paper model T = L/F, 3DGates Eq. 2"}


def format_report(r, time_model: str = "planner", energy_time_model: str = "paper",
                  paper_time_s: float | None = None) -> str:
    total = r.energy_j or 1.0
    other = ("--time-model paper" if time_model == "planner" else "--time-model planner")
    lines = [
        f"file        {r.source}",
        f"lines       {r.n_lines:,}   moves {r.n_moves:,}   timed steps {r.n_steps:,}",
        f"layers      {r.n_layers:,}   (found by {r.layer_method})",
        f"time        {r.time_s:,.1f} s ({_hms(r.time_s)})   {TIME_WORDS[time_model]}"
        + (f"; paper T = L/F {paper_time_s:,.1f} s" if paper_time_s is not None else "")
        + f" ({other})",
        f"energy      {r.energy_j:,.0f} J = {r.energy_j / 3600:,.2f} Wh   "
        f"mean power {r.mean_power_w:.2f} W   profile: {r.profile}",
        ("basis       the 3DGates power tables over the paper's T = L/F durations (Eq. 2): the energy "
         "`solve` and `verify` report (--energy-time-model planner: over the planner's)"
         if energy_time_model == "paper" else
         "basis       the 3DGates power tables over the planner model's durations (--energy-time-model "
         "paper: over T = L/F, the energy `solve` and `verify` report)"),
        "",
        "energy sectors (3DGates Fig. 5)",
    ]
    for s in SECTORS:
        v = r.sectors_j.get(s, 0.0)
        name = f"{s} motor" if len(s) == 1 else s
        lines.append(f"  {name:10s} {v / 3600:10.2f} Wh  {100 * v / total:5.1f} %")
    lines.append("")
    lines.append(f"by step kind        time s     energy Wh   (time: {time_model} model)")
    for k, t in r.by_kind_s.items():
        lines.append(f"  {k:12s} {t:12,.1f} {r.by_kind_j[k] / 3600:12.2f}")
    return "\n".join(lines)


def format_layers(r) -> str:
    out = ["layer     z mm      time s   energy J"]
    for i, (z, t, e) in enumerate(zip(r.layer_z_mm, r.layer_time_s, r.layer_energy_j)):
        out.append(f"{i:5d} {z:9.3f} {t:11.2f} {e:10.1f}")
    return "\n".join(out)
