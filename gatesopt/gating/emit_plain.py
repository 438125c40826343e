"""The unrotated emitter over arrays: where each instruction goes is decided with numpy (the same
rules as the per-line loop of ``emit.render``), the text is written by the compiled pass
``_emit_kernel.render_plain``; the split moves it leaves (an arc, an unusual spelling, a rounding
tie) are written by ``emit_line.LineRewriter``, the reference it must equal byte for byte.
"""
from __future__ import annotations

import numpy as np

from ..program import AXES, Kind, Program
from .emit_line import EmitResult, LineRewriter
from .placement import PlacedArrays
from .timeline import whole_steps


def instruction_table(fw):
    """The instruction lines of each (direction, motors) code ``16 * on + motor mask``, as texts
    (a list per code) and as the kernel's table: (texts, code_ptr (33,), txt_id, txt_buf, txt_ptr,
    bytes per code (32,) without line endings)."""
    texts = [fw.on_lines(motors) if code >= 16 else fw.off_lines(motors)
             for code in range(32) for motors in [tuple(a for m, a in enumerate(AXES) if code >> m & 1)]]
    distinct = list(dict.fromkeys(t for lines in texts for t in lines))
    blobs = [t.encode("utf-8", "surrogateescape") for t in distinct]
    txt_ptr = np.concatenate([[0], np.cumsum([len(b) for b in blobs])]).astype(np.int64)
    txt_id = np.array([distinct.index(t) for lines in texts for t in lines], np.int64)
    code_ptr = np.concatenate([[0], np.cumsum([len(lines) for lines in texts])]).astype(np.int64)
    cum = np.concatenate([[0], np.cumsum(np.diff(txt_ptr)[txt_id])]).astype(np.int64)
    return (texts, code_ptr, txt_id, np.frombuffer(b"".join(blobs), np.uint8), txt_ptr,
            cum[code_ptr[1:]] - cum[code_ptr[:-1]])


def render_plain(program: Program, fw, placed: PlacedArrays, rotation_deg: float, center_mm,
                 split_in_kernel: bool = True) -> EmitResult:
    """``emit.render`` without rotation, over arrays (module docstring); with
    ``split_in_kernel=False`` every split move is written by ``LineRewriter.rewrite`` (the
    reference the tests compare the kernel with)."""
    from . import _emit_kernel

    n = program.n_steps
    o = np.argsort(placed.time_s, kind="stable")         # time order; ties keep the given order
    row, on, split, frac = placed.row[o], placed.on[o], placed.split[o], placed.fraction[o]
    code = on.astype(np.int64) * 16 + placed.motor_mask[o]
    texts, code_ptr, txt_id, txt_buf, txt_ptr, code_bytes = instruction_table(fw)
    code_lines = np.diff(code_ptr)
    in_prog = row < n
    r0 = np.minimum(row, n - 1)
    line_r = program.line[r0]
    strictly_inside = split & (frac > 0.0) & (frac < 1.0)
    whole = whole_steps(program.steps_motor(), program.kind, fw.split_moves)
    unsplittable = in_prog & strictly_inside & whole[r0]
    live = ~unsplittable & (code_lines[code] > 0)
    cut = live & in_prog & split & ~(frac <= 0.0) & ~(frac >= 1.0)
    put = live & ~cut
    slot = np.where(~in_prog, program.line[n - 1] + 1,
                    np.where(~split | (frac <= 0.0), line_r, line_r + 1))
    instr = int(code_lines[code[live]].sum())
    # instruction lines before a line: (slot, rank, time order); rank 0 = an "off" moved out of the
    # step ending right before (first), 1 = placed there, 2 = an "on" moved out of the step there
    ins_slot, ins_rank, ins_code = [slot[put]], [np.ones(int(put.sum()), np.int64)], [code[put]]
    moved = int(unsplittable.sum())
    if moved:
        # A dwell, heat-up wait or homing cannot be split, nor an extrude-only move
        # (``timeline.whole_steps``). Per motor only the last instruction
        # inside it matters: a final "on" goes before the step, a final "off" after it -- both on
        # the safe side of start-ahead / end-late (the motor is on for the whole step).
        idx = np.flatnonzero(unsplittable)
        for r in dict.fromkeys(row[idx].tolist()):
            last = {}
            for k in idx[row[idx] == r]:
                for m in range(4):
                    if placed.motor_mask[o[k]] >> m & 1:
                        last[m] = bool(on[k])
            for is_on, at, rank in ((True, int(program.line[r]), 2), (False, int(program.line[r]) + 1, 0)):
                mask = sum(1 << m for m, v in last.items() if v is is_on)
                c = 16 * is_on + mask
                if mask and code_lines[c]:
                    instr += int(code_lines[c])
                    ins_slot.append(np.array([at]))
                    ins_rank.append(np.array([rank]))
                    ins_code.append(np.array([c]))
    ins_slot, ins_rank, ins_code = (np.concatenate(v).astype(np.int64) for v in (ins_slot, ins_rank, ins_code))
    oi = np.lexsort((np.arange(len(ins_slot)), ins_rank, ins_slot))
    ins_slot, ins_code = ins_slot[oi], ins_code[oi]
    # cuts: by row, then fraction (stable: moments at one fraction keep their time order)
    c_row, c_frac, c_code = row[cut], frac[cut], code[cut]
    oc = np.argsort(c_frac, kind="stable")
    oc = oc[np.argsort(c_row[oc], kind="stable")]
    c_row, c_frac, c_code = c_row[oc], c_frac[oc], c_code[oc]
    split_rows, cut_start = np.unique(c_row, return_index=True)
    cut_ptr = np.append(cut_start, len(c_row)).astype(np.int64)
    split_line = program.line[split_rows].astype(np.int64)
    nl = program.line_ending.encode()
    ls = program.line_start
    line_len = ls[split_line + 1] - ls[split_line]
    cap = (len(program.data) + int((code_bytes[ins_code] + len(nl) * code_lines[ins_code]).sum())
           + int((code_bytes[c_code] + len(nl) * code_lines[c_code]).sum())
           + int(((np.diff(cut_ptr) + 1) * (line_len + 100 + len(nl))).sum()))
    out = np.empty(cap, np.uint8)
    left_at = np.full(len(split_rows), -1, np.int64)
    buf = np.frombuffer(program.data, np.uint8)
    size, added = _emit_kernel.render_plain(
        buf, ls, ins_slot, ins_code, split_rows.astype(np.int64), split_line, cut_ptr, c_frac, c_code,
        code_ptr, txt_id, txt_buf, txt_ptr, np.frombuffer(nl, np.uint8), program.kind == Kind.ARC,
        program.start_mm, program.end_mm, program.offset_mm, program.relative_xyz, program.relative_e,
        program.inch, split_in_kernel, out, left_at)
    added += int(code_lines[ins_code].sum())
    pieces, at = [], 0
    em = LineRewriter(program, 0.0, (0.0, 0.0), None, None)
    for k in np.flatnonzero(left_at >= 0):
        # a split the kernel leaves (an arc, an unusual spelling, a rounding tie): the reference
        r = int(split_rows[k])
        cuts = []
        for f, c in zip(c_frac[cut_ptr[k]:cut_ptr[k + 1]].tolist(), c_code[cut_ptr[k]:cut_ptr[k + 1]].tolist()):
            if cuts and f - cuts[-1][0] <= 1e-12:      # several lines at one moment: one split
                cuts[-1] = (cuts[-1][0], cuts[-1][1] + texts[c])
            else:
                cuts.append((f, list(texts[c])))
        new = em.rewrite(r, cuts)
        text = program.line_text(int(split_line[k]))
        ending = text[len(text.rstrip("\r\n")):]
        pieces += [out[at:left_at[k]], "".join(x + program.line_ending for x in new[:-1]).encode(
            "utf-8", "surrogateescape") + (new[-1] + ending).encode("utf-8", "surrogateescape")]
        at = int(left_at[k])
        added += len(new) - 1
    pieces.append(out[at:size])
    data = b"".join(pieces) if len(pieces) > 1 else out[:size].tobytes()
    notes = (f"{moved} instruction(s) moved out of a dwell/wait/homing step to its safe side",) if moved else ()
    return EmitResult(data.decode("utf-8", "surrogateescape"), added, instr, len(split_rows), moved, 0.0,
                      rotation_deg, (float(center_mm[0]), float(center_mm[1])), notes)
