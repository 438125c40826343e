"""Native solver output never reaches standard output (which carries G-code with `-o -`)."""
from __future__ import annotations

import subprocess
import sys


def test_c_printf_inside_the_guard_goes_to_stderr():
    code = ("import ctypes, sys\n"
            "from gatesopt._native import native_stdout_to_stderr\n"
            "libc = ctypes.CDLL(None)\n"
            "print('before', flush=True)\n"
            "with native_stdout_to_stderr():\n"
            "    libc.printf(b'native debug line\\n')\n"
            "print('after', flush=True)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout == "before\nafter\n"
    assert "native debug line" in r.stderr
