"""The kernels' cache follows the sources: numba keys a cached kernel on its own file only, so a
change in a module a kernel inlines from must still give a fresh cache (gatesopt._jit)."""
from __future__ import annotations

import os
from pathlib import Path

import numba
import pytest

import gatesopt
from gatesopt._jit import source_digest


def test_digest_changes_with_any_module(tmp_path):
    (tmp_path / "a.py").write_text("X = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("Y = 2\n")
    d0 = source_digest(tmp_path)
    assert source_digest(tmp_path) == d0
    (tmp_path / "sub" / "b.py").write_text("Y = 3\n")      # same size, other bytes
    d1 = source_digest(tmp_path)
    assert d1 != d0
    (tmp_path / "sub" / "b.py").rename(tmp_path / "sub" / "c.py")
    assert source_digest(tmp_path) != d1


@pytest.mark.skipif(bool(os.environ.get("NUMBA_CACHE_DIR")), reason="NUMBA_CACHE_DIR set by the user")
def test_the_package_caches_under_its_sources_digest():
    pkg = Path(gatesopt.__file__).resolve().parent
    assert Path(numba.config.CACHE_DIR) == pkg / "__pycache__" / f"numba-{source_digest(pkg)}"
