"""Corpus scale: every file through solve + verify, one result row per (file, formulation).

The unit of work is ``process_file`` (a pure library call, picklable), so the same rows come from
a local process pool or a Dask cluster (``run_batch(..., dask="tcp://...")``): nothing home-made
for scheduling. The 3DGates paper evaluated 338 files / 71 M lines this way (Section 5.1).
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .errors import GatesoptError
from .program import Program

# columns of a result row, in CSV order; timing columns vary run to run (TIMING_COLUMNS)
COLUMNS = (
    "file", "formulation", "verified", "error", "slicer", "flavor", "infill_pattern", "lines", "layers",
    "energy_before_j", "energy_after_j", "saving_pct", "print_time_before_s", "print_time_after_s",
    "print_time_change_pct", "print_time_model", "paper_time_before_s", "paper_time_after_s",
    "added_time_pct", "paper_added_time_pct", "lines_before", "lines_after", "lines_added", "bytes_before", "bytes_after",
    "size_change_pct", "rotation_deg", "status", "stopped", "gap", "objective_j", "bound", "ordered",
    "travel_before_mm", "travel_after_mm", "travel_reduction_pct", "max_curves_per_layer",
    "off_time_X_s", "off_time_Y_s", "off_time_Z_s", "off_time_E_s", "max_snap_mm", "firmware",
    "firmware_line", "rotation_line", "findings", "warnings", "output", "solve_s", "wall_s",
)
TIMING_COLUMNS = ("solve_s", "wall_s")


@dataclass(frozen=True)
class BatchOptions:
    """What every file gets (plain values, so the options travel to worker processes)."""

    formulation: str = "dp"
    firmware: str = "auto"              # read from each file (``rewrite.printer.choose``), or a name
    force_firmware: bool = False        # write ``firmware``'s lines whatever the file says
    motors: tuple | None = None         # None: X, Y (what the firmware may gate of them)
    rotate: str = "auto"
    bed_size_mm: tuple | None = None    # None: the bed each file names (no bed: not rotated)
    start_ahead_s: float = 1.8e-3
    end_late_s: float = 1.0e-3
    max_added_time_pct: object = "default"    # "default": 1 % for stock firmware; None: no budget
    max_added_lines_pct: float | None = None
    time_limit_s: float | None = 60.0
    budget_s: float | None = 10.0       # the whole run of a file, as `gatesopt solve --budget`
    order_mode: str = "safe"            # the curve ordering's mode, as `gatesopt solve --order-mode`
    order_workers: int = 1              # processes of the ordering (2: as `solve` on 2 cores)
    order: bool = True
    gating: bool = True
    profile: str = "paper"
    write_dir: str | None = None        # write each verified output here (never an unverified one)
    printer_config: str | None = None   # the printer's Klipper config (``--printer-config``), a path


def max_curves_per_layer(order_problem) -> int:
    """Curves in the layer with the most (Fleming et al.'s measure of a model's ordering difficulty)."""
    layers = order_problem.curve_layer
    return int(np.bincount(layers).max()) if len(layers) else 0


def _infill_pattern(program: Program) -> str:
    import re
    head = program.data[:100_000] + program.data[-100_000:]
    m = re.search(rb"(?:^|\n);[ \t]*(?:fill_pattern|sparse_infill_pattern|infill_pattern)[ \t]*=[ \t]*([\w-]+)", head)
    if m:
        return m.group(1).decode()
    m = re.search(rb"infill_pattern = ([\w-]+)", head)      # Cura's ;SETTING_3 block
    return m.group(1).decode() if m else ""


STDIN_FILE = "-"        # a path that means the G-code given on standard input (``data``)


def output_name(path: str) -> str:
    """The name of ``path``'s output under ``--write-dir`` (``.gz`` dropped)."""
    return "stdin.gcode" if path == STDIN_FILE else Path(path).name.removesuffix(".gz")


def process_file(path: str, options: BatchOptions, data: bytes | None = None) -> dict:
    """Solve + verify one file; a row of ``COLUMNS``. Never raises: errors become the ``error``
    column. ``data``: the G-code itself, for the path ``-`` (standard input, read once by the
    caller)."""
    from .ordering import OrderingOptions
    from .rewrite.pipeline import order_formulation_of, run
    from .rewrite.printer import DEFAULT, choose
    from .parse import parse

    t0, cpu0 = time.perf_counter(), time.process_time()
    row = {c: "" for c in COLUMNS}
    row.update(file=str(path), formulation=options.formulation, verified=False)
    try:
        program = parse(data, source="<stdin>") if path == STDIN_FILE else parse(path)
        row["warnings"] = " | ".join(program.warnings)[:2000]
        row.update(slicer=program.header.get("slicer", ""), flavor=program.header.get("flavor", ""),
                   infill_pattern=_infill_pattern(program), lines=program.n_lines, layers=program.n_layers)
        budget = options.max_added_time_pct
        extra = {}
        if options.printer_config:
            # read in each worker (a path travels to worker processes; the config is small)
            from .printer_config import read_printer_config
            extra["printer"] = read_printer_config(options.printer_config)
        choice = choose(program, options.firmware, force=options.force_firmware,
                        max_added_time_pct=DEFAULT if budget == "default" else budget,
                        motors=None if options.motors is None else tuple(options.motors),
                        rotate=options.rotate, start_ahead_s=options.start_ahead_s,
                        end_late_s=options.end_late_s, max_added_lines_pct=options.max_added_lines_pct,
                        profile=options.profile, bed_size_mm=options.bed_size_mm, **extra)
        # as `gatesopt solve` runs a file: the same whole-run budget, ordering mode and formulation
        # choice (the one the gating formulation names: milp, cpsat, greedy; auto for dp), so that
        # a row's figures are the ones `solve` gives for that file
        order_formulation = order_formulation_of(options.formulation)
        res = run(program, choice.options, formulation=options.formulation, time_limit_s=options.time_limit_s,
                  order=options.order, gating=options.gating and choice.options is not None, choice=choice,
                  budget_s=options.budget_s, order_options=OrderingOptions(mode=options.order_mode),
                  started_s=t0, cpu_started_s=cpu0, order_workers=options.order_workers,
                  order_formulation=order_formulation)
        s = res.summary()
        for k in COLUMNS:
            if k in s and not isinstance(s[k], (dict, list)):
                row[k] = s[k]
        for m, v in (s.get("off_time_s") or {}).items():
            row[f"off_time_{m}_s"] = v
        row["findings"] = " | ".join(s.get("findings", []))[:2000]
        row["verified"] = bool(s.get("verified"))
        if res.order_problem is not None:
            row["max_curves_per_layer"] = max_curves_per_layer(res.order_problem)
        # travel as every report measures it (``rewrite.figures``: on the files, first layer on)
        tb, ta = s["travel_before_mm"], s["travel_after_mm"]
        row["travel_reduction_pct"] = 100.0 * (1.0 - ta / tb) if tb > 0 else 0.0
        if options.write_dir and row["verified"]:
            out = Path(options.write_dir) / output_name(path)
            out.parent.mkdir(parents=True, exist_ok=True)
            tmp = out.with_name(out.name + f".tmp-{os.getpid()}")
            tmp.write_text(res.text, encoding="utf-8", errors="surrogateescape", newline="")
            os.replace(tmp, out)
            row["output"] = str(out)
    except GatesoptError as exc:
        row["error"] = str(exc)
    except Exception as exc:  # a bug must not stop the other files: report it in the row
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        row["error"] = (f"internal error: {type(exc).__name__}: {exc} "
                        f"(at {Path(frame.filename).name}:{frame.lineno}; please report it)")
    row["wall_s"] = time.perf_counter() - t0
    return row


# ------------------------------------------------------------------------------------------------
def expand_paths(paths) -> list[str]:
    """Files and folders (G-code files inside, sorted) to a list of files (``-``: standard input,
    kept as it is)."""
    out = []
    for p in paths:
        if p == STDIN_FILE:
            out.append(p)
            continue
        p = Path(p)
        if p.is_dir():
            out += sorted(str(q) for q in p.iterdir()
                          if q.name.endswith((".gcode", ".gcode.gz", ".gco", ".g")) and q.is_file())
        elif p.exists():
            out.append(str(p))
        else:
            raise GatesoptError(f"{p}: no such file or folder")
    return out


def read_rows(path) -> list[dict]:
    """Rows of an earlier results file (CSV or JSON), for --resume and for reports; none when
    ``path`` does not exist. Raises ``GatesoptError`` for a file that is not a results file."""
    path = Path(path)
    if not path.exists():
        return []
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise GatesoptError(f"{path}: not a results file of gatesopt batch (not text)") from None
    return parse_rows(text, str(path), json_rows=path.suffix == ".json")


def parse_rows(text: str, name: str, json_rows: bool | None = None) -> list[dict]:
    """The rows of a results file's ``text`` (JSON, or CSV; ``json_rows`` None: JSON if it starts
    with ``[``); ``name`` for messages."""
    what = f"{name}: not a results file of gatesopt batch"
    if json_rows is None:
        json_rows = text.lstrip().startswith("[")
    if json_rows:
        try:
            rows = json.loads(text or "[]")
        except ValueError as exc:
            raise GatesoptError(f"{what} (bad JSON: {exc})") from None
        if not isinstance(rows, list) or not all(isinstance(r, dict) and "file" in r for r in rows):
            raise GatesoptError(f"{what} (JSON that is not a list of rows with a 'file')")
        return rows
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        fields = reader.fieldnames or []
        if "file" not in fields or "formulation" not in fields:
            raise GatesoptError(f"{what} (a CSV whose first line names its columns, 'file' and "
                                "'formulation' among them)")
        return [_typed(r) for r in reader]
    except csv.Error as exc:
        raise GatesoptError(f"{what} ({exc})") from None


def _typed(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if v in ("True", "False"):
            out[k] = v == "True"
        else:
            try:
                out[k] = float(v) if v not in ("", None) and k not in ("file", "formulation", "error", "slicer",
                                                                        "flavor", "infill_pattern", "status",
                                                                        "firmware", "findings", "warnings", "output") else v
            except ValueError:
                out[k] = v
    return out


class ResultWriter:
    """Appends rows as they arrive (CSV) or keeps them for one JSON write, so an interrupted batch
    keeps what it finished and ``--resume`` can pick up."""

    def __init__(self, path, resume_rows: list[dict]):
        self.path = Path(path)
        self.json = self.path.suffix == ".json"
        self.rows = list(resume_rows)
        if not self.json:
            new = not (resume_rows and self.path.exists())
            self.f = open(self.path, "a" if not new else "w", newline="")
            self.w = csv.DictWriter(self.f, fieldnames=COLUMNS, extrasaction="ignore")
            if new:
                self.w.writeheader()
                for r in resume_rows:
                    self.w.writerow(r)

    def add(self, row: dict):
        self.rows.append(row)
        if self.json:
            tmp = self.path.with_name(self.path.name + ".tmp")
            tmp.write_text(json.dumps(self.rows, indent=1, default=_json_default))
            os.replace(tmp, self.path)
        else:
            self.w.writerow(row)
            self.f.flush()

    def close(self):
        if not self.json:
            self.f.close()


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def run_batch(paths, options: BatchOptions, *, out=None, jobs: int = 1, resume: bool = False,
              dask: str | None = None, progress: bool = True, formulations: tuple | None = None,
              stdin_data: bytes | None = None) -> list[dict]:
    """Every (file, formulation) through ``process_file``; rows in the order of ``paths``.
    ``stdin_data``: the G-code of the path ``-`` (standard input, read by the caller)."""
    files = expand_paths(paths)
    forms = formulations or (options.formulation,)
    todo = [(f, fm) for f in files for fm in forms]
    done_rows = read_rows(out) if (resume and out) else []
    done = {(r["file"], r["formulation"]) for r in done_rows}
    todo = [t for t in todo if t not in done]
    writer = ResultWriter(out, done_rows) if out else None
    rows = {}
    bar = _progress(len(todo), progress)
    work = [(f, _with(options, formulation=fm), stdin_data if f == STDIN_FILE else None) for f, fm in todo]
    try:
        for key, row in _execute(work, jobs, dask):
            rows[key] = row
            if writer:
                writer.add(row)
            bar.update(1)
            bar.set_postfix_str(Path(row["file"]).name[:30] + (" ERROR" if row["error"] else ""))
    finally:
        bar.close()
        if writer:
            writer.close()
    ordered = done_rows + [rows[(f, fm)] for f, fm in todo if (f, fm) in rows]
    return ordered


def _with(options: BatchOptions, **changes) -> BatchOptions:
    d = asdict(options)
    d.update(changes)
    return BatchOptions(**d)


def text_size(path) -> int:
    """Bytes of G-code text in ``path``: a gzip file's own record of its uncompressed size (its
    last 4 bytes, modulo 4 GiB), else the file's size."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if path.suffix == ".gz" and size >= 18:
            with open(path, "rb") as f:
                f.seek(-4, os.SEEK_END)
                return int.from_bytes(f.read(4), "little")
        return size
    except OSError:
        return 0


def largest_first(work: list) -> list:
    """``work`` with the largest files first: with several workers, a large file started last
    would be the only one still running (longest processing time first, Graham 1969)."""
    return sorted(work, key=lambda item: -text_size(item[0]))


def _execute(work, jobs: int, dask: str | None):
    """Yield ((file, formulation), row) as results arrive; with more than one worker the largest
    files go first (``largest_first``)."""
    if jobs > 1 or dask:
        work = largest_first(work)
    if dask:
        from distributed import Client, LocalCluster, as_completed as dask_completed
        if dask == "local":
            cluster = LocalCluster(n_workers=max(jobs, 1), threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            client = Client(cluster)
        else:
            cluster, client = None, Client(dask)
        try:
            futures = {client.submit(process_file, f, o, d, pure=False): (f, o.formulation) for f, o, d in work}
            for fut in dask_completed(futures):
                yield futures[fut], fut.result()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return
    if jobs <= 1:
        for f, o, d in work:
            yield (f, o.formulation), process_file(f, o, d)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(process_file, f, o, d): (f, o.formulation) for f, o, d in work}
        for fut in as_completed(futures):
            yield futures[fut], fut.result()


def _progress(total: int, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total, unit="file", disable=not enabled, dynamic_ncols=True,
                bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}, {rate_fmt}] {postfix}")


def summarize(rows: list[dict]) -> dict:
    ok = [r for r in rows if r.get("verified") in (True, "True") and not r.get("error")]
    sav = [float(r["saving_pct"]) for r in ok if r.get("saving_pct") not in ("", None)]
    return {"files": len(rows), "verified": len(ok), "errors": sum(1 for r in rows if r.get("error")),
            "mean_saving_pct": float(np.mean(sav)) if sav else math.nan,
            "max_saving_pct": float(np.max(sav)) if sav else math.nan}
