"""Files of any size in bounded memory: read, profile and gate G-code chunk by chunk.

A whole-file Program holds about 8x the file's size in arrays; a 1 GB file would need 8 GB. Here the
file is read in chunks that end at a line boundary; the parser's modal state (position, G92
offsets, G90/G91, M82/M83, units, feed, fan, temperatures, motor enables) is carried from one chunk
to the next (``gatesopt.parse(..., state=...)``), so each chunk's Program is exactly the rows the
whole-file parse would give. Peak memory is about 9x the chunk size, whatever the file size.

Gating chunk by chunk keeps every motor on at each chunk boundary (the next chunk starts from the
file's own enable state): the off interval that would run from a motor's last step to the chunk's
end is dropped, one gap per motor per chunk of millions of lines.
"""
from __future__ import annotations

import dataclasses
import gzip
import os
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from . import _scan, slicers
from .energy import EnergyReport, load_profile
from .errors import GatesoptError, GcodeError
from .firmware import FirmwareError
from .kinematics import check_gateable
from .limits import PieceLimits
from .parse import BGCODE_MAGIC, DEFAULT_FEED_MM_S, GZIP_MAGIC, PER_COMMAND_WORDS, parse
from .rewrite.figures import profile_report
from .rewrite.printer import file_firmware

DEFAULT_CHUNK_BYTES = 64 << 20


def iter_chunks(path, chunk_bytes: int = DEFAULT_CHUNK_BYTES):
    """Yield (bytes, first_line_number_0_based) pieces of a file, each ending at a line boundary."""
    p = Path(path)
    try:
        head = p.open("rb").read(4)
    except FileNotFoundError:
        raise GcodeError(str(p), None, "no such file") from None
    except OSError as exc:
        raise GcodeError(str(p), None, f"cannot read: {exc.strerror}") from None
    if head[:4] == BGCODE_MAGIC:
        raise GcodeError(str(p), None, "binary G-code (.bgcode) is not supported: turn off "
                         "'Supports binary G-code' in PrusaSlicer and export again")
    f = gzip.open(p, "rb") if head[:2] == GZIP_MAGIC else p.open("rb")
    line0 = 0
    rest = b""
    with f:
        while True:
            block = f.read(chunk_bytes)
            if not block:
                break
            data = rest + block
            cut = data.rfind(b"\n") + 1
            if cut == 0:            # a line longer than a chunk: keep reading
                rest = data
                continue
            piece, rest = data[:cut], data[cut:]
            yield piece, line0
            line0 += piece.count(b"\n")
    if rest:
        yield rest, line0


#: the count ``parse.per_command`` gives a warning said of more lines
_MORE = re.compile(r" \((\d+) more (\S+) lines like it\)$")


def _warning_kind(message: str, prog=None, line0: int = 0) -> str:
    """A parse warning without its place and counts: each chunk finds the same M101 or foreign
    axis again, and the user needs to read it once (with the first line where it applies). A
    warning quoting its line's text (``parse.per_command``: one per command) is of its command,
    whatever the rest of that line (Bambu's base64 ``M624`` lines differ in letters)."""
    if prog is not None and message.startswith(prog.source + ":"):
        m = re.match(r"(\d+): ", message[len(prog.source) + 1:])
        local = int(m.group(1)) - 1 - line0 if m else -1
        if 0 <= local < len(prog.line_start) - 1:
            text = prog.data[prog.line_start[local]:prog.line_start[local + 1]]
            text = text.decode("utf-8", "replace").strip()[:60]
            after = message[len(prog.source) + 1 + m.end():]
            if text and after.startswith(text + ": "):
                from ._text import code_words
                return (code_words(text) or [text])[0] + "|" + re.sub(r"\d+", "#", after[len(text):])
    return re.sub(r"\d+", "#", message)


def _keep_new_warnings(prog, warnings: list, warned: dict, line0: int = 0) -> None:
    """Append ``prog``'s parse warnings of a kind not given yet (``_warning_kind``); a per-command
    one (``parse.per_command``) given already is counted instead: its line says how many more
    lines, over every chunk so far, it is said of, as ``parse`` of the whole file says."""
    for w in prog.warnings:
        m = _MORE.search(w)
        base, n = (w[:m.start()], 1 + int(m.group(1))) if m else (w, 1)
        kind = _warning_kind(base, prog, line0)
        if kind not in warned:
            warned[kind] = [len(warnings), n, base]
            warnings.append(w)
        elif "|" in kind and any(word in kind for word in PER_COMMAND_WORDS):
            k = warned[kind]
            k[1] += n
            warnings[k[0]] = f"{k[2]} ({k[1] - 1} more {kind.split('|')[0]} lines like it)"


def _parse_piece(piece: bytes, name: str, state, line0: int, flavor: str | None):
    return parse(piece, source=name, state=state, line_offset=line0, flavor=flavor, require_moves=False)


def profile_stream(path, profile_name: str = "paper", chunk_bytes: int = DEFAULT_CHUNK_BYTES,
                   progress=None, time_model: str = "paper",
                   energy_time_model: str | None = None) -> EnergyReport:
    """``energy.profile`` of a file of any size, chunk by chunk (per-step arrays are not kept).

    ``time_model``: the times reported (total, by kind, per layer); ``energy_time_model`` (default:
    the same): the durations the energy integrates over (``gatesopt profile`` keeps the paper's,
    as ``solve`` and ``verify`` do, and reports the planner's time).
    With a "planner" model the planner rules, the printer and the slicer's config block are read
    once, from the file's head and tail (``_head_and_tail``: PrusaSlicer writes its config block
    at the end), and each chunk's limit lines apply from their lines on, carried to the chunks
    after it (``limits.PieceLimits``), as in the whole file; each chunk is planned on its own:
    the look-ahead restarts at a chunk boundary, a few moves in millions.
    """
    energy_time_model = energy_time_model or time_model
    prof = load_profile(profile_name)
    state = _scan.initial_state(prof.time.ambient_c if prof.kind == "table" else 25.0, DEFAULT_FEED_MM_S)
    name = str(path)
    tot = defaultdict(float)
    sectors = defaultdict(float)
    by_kind_j, by_kind_s = defaultdict(float), defaultdict(float)
    layer_t, layer_e, layer_z = [], [], []
    n_lines = n_steps = n_moves = 0
    flavor = None
    warnings, warned = [], {}
    method = ""
    any_moves = False
    last_ext_z = np.nan         # Z where the previous chunk's last extrusion ended
    pieces = None               # the limits in force where the next chunk starts
    firmware = None             # the file's printer's (its stalls count, as in `profile`)
    planned = "planner" in (time_model, energy_time_model)
    for piece, line0 in iter_chunks(path, chunk_bytes):
        prog = _parse_piece(piece, name, state, line0, flavor)
        if flavor is None:      # the header (first chunk) says which G90/G91 semantics apply
            flavor = prog.header.get("flavor", "") or "marlin"
            # the printer, the planner's rules and the slicer's config block are in the file's
            # head and tail: read once (a middle chunk has none of them)
            settings = parse(_head_and_tail(Path(path)), source=name, flavor=flavor,
                             require_moves=False)
            firmware = file_firmware(settings)[1]
            pieces = PieceLimits.of_settings(settings) if planned else None
        _keep_new_warnings(prog, warnings, warned, line0)
        n_lines += prog.n_lines
        limits = None
        if pieces is not None:      # a chunk's limit lines apply to the chunks after it too
            limits, pieces = pieces.of_piece(prog)
        if prog.n_steps == 0:
            continue
        any_moves = any_moves or bool((prog.kind <= 5).any())
        r, dur = profile_report(prog, prof, time_model, energy_time_model, firmware, limits)
        tot["time"] += r.time_s
        tot["energy_time"] += r.time_s if r.energy_time_s is None else r.energy_time_s
        tot["energy"] += r.energy_j
        n_steps += r.n_steps
        n_moves += r.n_moves
        for k, v in r.sectors_j.items():
            sectors[k] += v
        for k, v in r.by_kind_j.items():
            by_kind_j[k] += v
            by_kind_s[k] += r.by_kind_s[k]
        # steps before this chunk's first layer marker belong to the previous chunk's last layer
        pre = prog.layer < 0
        if pre.any() and layer_t:
            d = dur[pre]
            layer_t[-1] += float(d.sum())
            layer_e[-1] += float(r.step_energy_j[pre].sum())
        lt, le, lz = r.layer_time_s.tolist(), r.layer_energy_j.tolist(), prog.layer_z_mm.tolist()
        ext = np.flatnonzero(prog.extruding)
        # parse.py's rule across the boundary: the chunk's first extrusion continues the last layer
        # when it starts at the Z where the previous chunk's last extrusion ended
        continues = bool(lz and layer_z) and len(ext) > 0 and abs(prog.start_mm[ext[0], 2] - last_ext_z) < 1e-6
        if len(ext):
            last_ext_z = float(prog.end_mm[ext[-1], 2])
        if prog.layer_method == "z-change" and continues:
            # a layer found by Z changes (parse.py's fallback rule: a new layer needs a new Z reached
            # by a non-extruding move) that the chunk boundary cut in two: one layer again
            layer_t[-1] += lt.pop(0)
            layer_e[-1] += le.pop(0)
            lz.pop(0)
        layer_t += lt
        layer_e += le
        layer_z += lz
        method = method or prog.layer_method
        if progress:
            progress(line0 + prog.n_lines)
    if n_lines == 0:
        raise GcodeError(name, None, "empty file: no G-code in it")
    if not any_moves:
        raise GcodeError(name, None, "no moves: no G0/G1/G2/G3 line with a coordinate")
    empty = np.zeros(0)
    return EnergyReport(
        source=name, profile=prof.name, n_lines=n_lines, n_steps=n_steps, n_moves=n_moves,
        n_layers=len(layer_z), time_s=tot["time"], energy_j=tot["energy"], sectors_j=dict(sectors),
        energy_time_s=tot["energy_time"],
        by_kind_j=dict(by_kind_j), by_kind_s=dict(by_kind_s), layer_time_s=np.array(layer_t),
        layer_energy_j=np.array(layer_e), layer_z_mm=np.array(layer_z), step_energy_j=empty,
        step_end_s=empty, layer_method=(method + " (streamed)") if method else "streamed",
        warnings=tuple(warnings[:20]))


@dataclasses.dataclass(frozen=True)
class StreamGatingResult:
    chunks: int
    energy_before_j: float
    energy_after_j: float
    lines_before: int
    lines_after: int
    verified: bool
    findings: tuple
    warnings: tuple = ()        # the input's parse warnings, each kind once (as profile_stream's)

    @property
    def saving_pct(self) -> float:
        return 100.0 * (1.0 - self.energy_after_j / self.energy_before_j) if self.energy_before_j else 0.0


def _spaced_from_the_chunk_before(problem, sol, keep: np.ndarray) -> np.ndarray:
    """``keep`` less the first off intervals of each motor that a firmware timing its own switches
    (``options.schedule``: the klipper-gating module) would skip for rule B after the chunk before.

    The module sees the whole file: its rule B counts from the motor's last gated interval, which
    may be in the chunk before, its line and its "on" as late as that chunk's last row. So the first
    interval of a motor here is written only if rule B (``GatingProblem.spacing_ok``) holds after an
    interval whose off and on are both at this chunk's start (lower-bound clock 0); one that does
    not is dropped, and the next is checked the same way (within the chunk the solver's own rule B
    holds between those kept)."""
    if not problem.has_spacing:
        return keep
    idx = problem.idle_intervals_of(sol.angle_index)
    keep = keep.copy()
    for m in np.unique(sol.off_motor[keep]):
        mine = idx[problem.idle_motor[idx] == m]
        for j in np.flatnonzero(keep & (sol.off_motor == m)):      # in time order
            i = mine[np.argmin(np.abs(problem.idle_start_s[mine] - sol.off_start_s[j]))]
            if problem.spacing_ok(int(m), 0.0, 0.0, problem.idle_lb_off_s[i], problem.idle_lb_on_s[i]):
                break
            keep[j] = False
    return keep


def _head_and_tail(p: Path) -> bytes:
    """The whole lines of the file's first and last ``slicers.HEAD_BYTES`` (the whole file if it
    is shorter than both), a gzip file's too (its tail read through once)."""
    n = slicers.HEAD_BYTES
    with p.open("rb") as f:
        gz = f.read(2) == GZIP_MAGIC
    with (gzip.open if gz else open)(p, "rb") as f:
        head = f.read(n)
        if gz:                      # a gzip file cannot seek to its last n bytes: read through
            tail = b""
            while block := f.read(1 << 24):
                tail = (tail + block)[-n:]
        else:
            f.seek(max(len(head), p.stat().st_size - n))
            tail = f.read()
    if not tail:
        return head
    head = head[:head.rfind(b"\n") + 1] if len(head) == n else head
    cut = tail.find(b"\n") + 1
    return head + b"\n" + tail[cut:]


def _settings_bytes(p: Path, file_lines: bool = False) -> bytes:
    """The head and tail of the file (``slicers.HEAD_BYTES`` each), where slicers write their
    settings (the printer model); a gzip file's head only (its tail costs a whole read).
    ``file_lines``: the lines between them as empty lines (counted: a read of the whole file), so
    that a line number read in the tail is the file's."""
    with p.open("rb") as f:
        head = f.read(slicers.HEAD_BYTES)
        if head[:2] == GZIP_MAGIC:
            with gzip.open(p, "rb") as g:
                return g.read(slicers.HEAD_BYTES)
        tail_at = max(len(head), p.stat().st_size - slicers.HEAD_BYTES)
        skipped = 0 if tail_at == len(head) else 1     # the whole file: nothing between
        if file_lines:
            skipped = 0
            while f.tell() < tail_at:
                skipped += f.read(min(1 << 24, tail_at - f.tell())).count(b"\n")
        f.seek(tail_at)
        return head + b"\n" * skipped + f.read()


def gate_stream(path, out_path, *, formulation: str = "dp", firmware: str = "3dgates",
                motors=("X", "Y"), chunk_bytes: int = DEFAULT_CHUNK_BYTES, verify_chunks: bool = True,
                force: bool = False, progress=None, printer=None) -> StreamGatingResult:
    """Gate a file of any size chunk by chunk into ``out_path`` (temp file + rename, verified).

    No rotation (a rotation must be chosen over the whole print, which a stream cannot see first).
    ``printer``: the printer's Klipper config (``gatesopt.printer_config``) for ``klipper-gating``
    (the input shaper's window, the module's options), as ``GatingOptions.for_firmware`` takes it.
    """
    from .gating.emit import emit
    from .gating.options import GatingOptions
    from .gating.problem import build
    from .gating.scoring import score
    from .gating.solve import solve
    from .verify import verify

    out_path = Path(out_path)
    if out_path.exists() and not force:
        raise GatesoptError(f"{out_path}: exists; pass --force to overwrite it")
    opts = GatingOptions.for_firmware(firmware, motors=tuple(motors), rotate="none", printer=printer)
    name = str(path)
    try:
        check_gateable(_settings_bytes(Path(path)), opts.motors, printer, name)
    except FirmwareError:
        # refused: once more with the file's own line numbers for the message (a whole read,
        # paid only here)
        check_gateable(_settings_bytes(Path(path), file_lines=True), opts.motors, printer, name)
        raise
    state_in = _scan.initial_state(25.0, DEFAULT_FEED_MM_S)
    state_out = state_in.copy()
    tmp = out_path.with_name(out_path.name + f".tmp-{os.getpid()}")
    e_before = e_after = 0.0
    lines_before = lines_after = 0
    findings = []
    warnings, warned = [], {}
    chunks = 0
    flavor = None
    try:
        with open(tmp, "wb") as out:
            for piece, line0 in iter_chunks(path, chunk_bytes):
                chunks += 1
                prog = _parse_piece(piece, name, state_in, line0, flavor)
                prog.check_rewritable(line0)
                _keep_new_warnings(prog, warnings, warned, line0)
                if flavor is None:
                    flavor = prog.header.get("flavor", "") or "marlin"
                lines_before += prog.n_lines
                if not (prog.kind <= 5).any():
                    out.write(piece)
                    _parse_piece(piece, name + " (output)", state_out, line0, flavor)
                    lines_after += prog.n_lines
                    continue
                problem = build(prog, opts)
                sol = solve(problem, formulation)
                end = problem.total_s    # the chunk's timeline (time_before_s adds its own stalls)
                keep = sol.off_end_s < end - 1e-12        # motors on at the chunk boundary
                if chunks > 1:
                    keep = _spaced_from_the_chunk_before(problem, sol, keep)
                if not keep.all():
                    m, a, b = sol.off_motor[keep], sol.off_start_s[keep], sol.off_end_s[keep]
                    sc = score(problem, m, a, b)
                    sol = dataclasses.replace(sol, off_motor=m, off_start_s=a, off_end_s=b,
                                              energy_j=sc.energy_j, lines_added=sc.lines_added,
                                              added_time_s=sc.added_time_s)
                text = emit(prog, sol, firmware=firmware)
                data = text.encode("utf-8", "surrogateescape")
                out.write(data)
                state_before_out = state_out.copy()
                outp = _parse_piece(data, name + " (output)", state_out, line0, flavor)
                lines_after += outp.n_lines
                e_before += sol.energy_before_j
                e_after += sol.energy_j
                if verify_chunks:
                    rep = verify(prog, outp, firmware=firmware, start_ahead_s=opts.start_ahead_s,
                                 end_late_s=opts.end_late_s, claimed=(sol.energy_j, sol.time_after_s),
                                 printer=printer)
                    if not rep.ok:
                        findings += [f"chunk {chunks}: {f}" for f in rep.findings[:5]]
                del prog, outp, problem, sol, text, data, state_before_out
                if progress:
                    progress(line0)
        if findings:
            raise GatesoptError(f"{name}: verification failed, nothing written: {findings[0]}")
        os.replace(tmp, out_path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return StreamGatingResult(chunks, e_before, e_after, lines_before, lines_after, not findings,
                              tuple(findings), tuple(warnings[:20]))
