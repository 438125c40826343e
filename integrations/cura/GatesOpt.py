# gatesopt post-processing script for Ultimaker Cura (Extensions > Post Processing > Modify G-Code).
#
# Install: copy this file into Cura's user "scripts" folder (Help > Show Configuration Folder, then
# the "scripts" subfolder; create it if missing) and restart Cura. gatesopt itself must be installed
# in a Python 3.11+ environment (README.md); set "gatesopt command" below to that environment's
# `gatesopt` executable if it is not on Cura's PATH.
#
# What it does: joins Cura's per-layer G-code chunks, re-orders curves and inserts motor
# power-gating instructions with gatesopt (every output is verified before it is used), and splits
# the result back into the same chunks. If anything fails, Cura's G-code is returned unchanged
# and a warning is shown: a post-processor must never damage a print.
from __future__ import annotations

import json
import shutil
import subprocess

try:  # inside Cura
    from ..Script import Script
except (ImportError, ValueError):  # pragma: no cover - outside Cura (tests provide a stand-in)
    from Script import Script  # type: ignore

try:
    from UM.Logger import Logger
    from UM.Message import Message
except ImportError:  # outside Cura
    Logger = None
    Message = None

POSTPROCESSED = ";POSTPROCESSED"


class GatesOpt(Script):
    """Energy-saving motor power gating (3DGates) and curve ordering by gatesopt."""

    def getSettingDataString(self) -> str:
        return json.dumps({
            "name": "gatesopt: motor power gating",
            "key": "GatesOpt",
            "metadata": {},
            "version": 2,
            "settings": {
                "formulation": {
                    "label": "Formulation", "description": "dp: exact and fast; milp/cpsat: exact with "
                    "budgets; greedy: the 3DGates paper's re-compiler", "type": "enum",
                    "options": {"dp": "dp", "milp": "milp", "cpsat": "cpsat", "greedy": "greedy"},
                    "default_value": "dp"},
                "firmware": {
                    "label": "Firmware", "description": "Which instructions to write and what they cost",
                    "type": "enum", "options": {"marlin": "Marlin (M18/M17)", "klipper": "Klipper",
                                                "3dgates": "3DGates patch (S0/S1)"},
                    "default_value": "marlin"},
                "motors": {"label": "Motors", "description": "Motors to gate, e.g. X,Y",
                           "type": "str", "default_value": "X,Y"},
                "max_added_time_pct": {
                    "label": "Max added time", "description": "Budget on print time added by firmware "
                    "stalls (Marlin/Klipper)", "unit": "%", "type": "float", "default_value": 1.0},
                "reorder": {"label": "Re-order curves", "description": "Cut travel by re-ordering "
                            "curves inside each layer (quality-safe mode)", "type": "bool",
                            "default_value": True},
                "rotate": {"label": "Rotate model", "description": "Let gatesopt rotate the print on "
                           "the bed (off keeps Cura's placement)", "type": "bool", "default_value": False},
                "time_limit": {"label": "Time limit", "description": "Seconds per solve", "unit": "s",
                               "type": "float", "default_value": 30.0},
                "command": {"label": "gatesopt command", "description": "Path of the gatesopt "
                            "executable (empty: find it on PATH, or use the library if Cura can import it)",
                            "type": "str", "default_value": ""},
            },
        })

    # -- helpers -------------------------------------------------------------------------------
    def _setting(self, key, default):
        try:
            v = self.getSettingValueByKey(key)
        except Exception:
            return default
        return default if v is None else v

    def _warn(self, text: str) -> None:
        if Logger is not None:
            Logger.log("w", "[gatesopt] %s", text)
        if Message is not None:
            try:
                Message(text=text, title="gatesopt: G-code left unchanged").show()
            except Exception:
                pass

    def _options(self) -> dict:
        return {
            "formulation": str(self._setting("formulation", "dp")),
            "firmware": str(self._setting("firmware", "marlin")),
            "motors": str(self._setting("motors", "X,Y")),
            "max_added_time_pct": float(self._setting("max_added_time_pct", 1.0)),
            "reorder": bool(self._setting("reorder", True)),
            "rotate": bool(self._setting("rotate", False)),
            "time_limit": float(self._setting("time_limit", 30.0)),
            "command": str(self._setting("command", "") or ""),
        }

    @staticmethod
    def _cli_args(o: dict) -> list:
        args = ["solve", "-", "-o", "-", "--formulation", o["formulation"], "--firmware", o["firmware"],
                "--motors", o["motors"], "--rotate", "auto" if o["rotate"] else "none",
                "--time-limit", str(o["time_limit"])]
        if o["firmware"] != "3dgates" and o["max_added_time_pct"] >= 0:
            args += ["--max-added-time-pct", str(o["max_added_time_pct"])]
        if not o["reorder"]:
            args.append("--no-order")
        return args

    def _optimize(self, text: str, o: dict) -> str:
        """The optimized G-code, or raise with a one-line reason."""
        command = o["command"] or shutil.which("gatesopt")
        if not command:
            try:  # Cura's own Python can import gatesopt: call the library directly
                from gatesopt.cli import main as gatesopt_main
            except ImportError:
                raise RuntimeError("gatesopt not found: install it and set 'gatesopt command'") from None
            return _run_in_process(gatesopt_main, self._cli_args(o), text)
        proc = subprocess.run([command, *self._cli_args(o)], input=text.encode("utf-8", "surrogateescape"),
                              capture_output=True, timeout=max(60.0, 20 * o["time_limit"]))
        if proc.returncode != 0:
            reason = proc.stderr.decode("utf-8", "replace").strip().splitlines()
            raise RuntimeError(reason[-1] if reason else f"gatesopt exited with {proc.returncode}")
        return proc.stdout.decode("utf-8", "surrogateescape")

    # -- Cura's entry point ----------------------------------------------------------------------
    def execute(self, data: list) -> list:
        if not data or POSTPROCESSED in data[0]:
            return data          # already post-processed: never run twice
        original = "".join(data)
        try:
            optimized = self._optimize(original, self._options())
            chunks = split_like(optimized, data)
        except Exception as exc:  # anything at all: the print must not suffer
            self._warn(f"optimization failed, G-code unchanged: {exc}")
            return data
        return chunks


def _run_in_process(main, args, text: str) -> str:
    import contextlib
    import io
    import sys
    stdin = io.TextIOWrapper(io.BytesIO(text.encode("utf-8", "surrogateescape")), encoding="utf-8",
                             errors="surrogateescape")
    out, err = io.BytesIO(), io.StringIO()
    stdout = io.TextIOWrapper(out, encoding="utf-8", errors="surrogateescape", write_through=True)
    old = sys.stdin, sys.stdout
    sys.stdin, sys.stdout = stdin, stdout
    try:
        with contextlib.redirect_stderr(err):
            code = main(args)
    finally:
        sys.stdin, sys.stdout = old
    if code != 0:
        lines = err.getvalue().strip().splitlines()
        raise RuntimeError(lines[-1] if lines else f"gatesopt exited with {code}")
    stdout.flush()
    return out.getvalue().decode("utf-8", "surrogateescape")


def split_like(text: str, chunks: list) -> list:
    """Split ``text`` into as many chunks as Cura's ``chunks``, cutting before the line each chunk
    starts with (';LAYER:n', the end code, ...), so that later scripts still see one layer per
    chunk. If a chunk's first line cannot be found in order, raise (the caller keeps Cura's G-code)."""
    lines = text.splitlines(keepends=True)
    cuts = [0]                              # line index where each chunk starts (None: empty chunk)
    i = 1
    for chunk in chunks[1:]:
        if not chunk:
            cuts.append(None)
            continue
        first = chunk.splitlines(keepends=True)[0]
        while i < len(lines) and lines[i] != first:
            i += 1
        if i == len(lines):
            raise RuntimeError(f"cannot find the chunk starting {first.strip()[:40]!r} in the output")
        cuts.append(i)
        i += 1
    cuts.append(len(lines))
    for k in range(len(cuts) - 2, 0, -1):   # an empty chunk starts (and ends) where the next begins
        if cuts[k] is None:
            cuts[k] = cuts[k + 1]
    return ["".join(lines[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
