"""Shared fixtures: where the development corpus lives (../shared/instances beside the repo)."""
from __future__ import annotations

import csv
import gzip
from pathlib import Path

import numpy as np

import pytest
from hypothesis import settings

# The property tests (parser, pipeline and gating fuzz) draw the same examples on every run, so a
# CI failure is a change in the code, never a new random draw. To search further, run with
# `pytest --hypothesis-profile=explore` (new random examples each run); a failure found that way
# is kept as a plain regression test (tests/test_verify_doubling_back.py has two).
settings.register_profile("default", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile("default")

REPO = Path(__file__).resolve().parents[1]
SHARED_INSTANCES = REPO.parent / "shared" / "instances"
PROJECT_INSTANCES = REPO / "instances"


def random_line_layers(sizes, seed=0):
    """One group per layer, random open lines (no two groups alike): ``from_polylines`` input for
    the ordering's budget tests."""
    rng = np.random.default_rng(seed)
    return [[rng.uniform(0, 60, (2, 2)) for _ in range(n)] for n in sizes]


def slicer_order(grp) -> np.ndarray:
    """The candidates of ``grp`` that print each curve as the slicer did (forwards, first seam)."""
    return np.flatnonzero(~grp.cand_reversed & (grp.cand_seam == 0))


def never_solve(grp, *, time_limit_s, **kw):
    """A formulation's ``solve`` that must not be called: the budget has ended."""
    raise AssertionError(f"a solver was called with {time_limit_s} s after the budget ended")


def shared_files() -> list[Path]:
    """Every G-code file of ../shared/instances (empty when the corpus is absent)."""
    if not (SHARED_INSTANCES / "MANIFEST.tsv").exists():
        return []
    return sorted(p for p in SHARED_INSTANCES.iterdir() if p.name.endswith((".gcode", ".gcode.gz")))


def manifest() -> dict[str, dict]:
    with open(SHARED_INSTANCES / "MANIFEST.tsv", newline="") as f:
        return {r["file"]: r for r in csv.DictReader(f, delimiter="\t")}


def read_bytes(path: Path) -> bytes:
    raw = path.read_bytes()
    return gzip.decompress(raw) if path.name.endswith(".gz") else raw


@pytest.fixture
def plan_as(monkeypatch):
    """``plan_as("marlin")``: every program the test plans without a family of its own is planned
    by that family's rules (``limits.default_family``, which otherwise reads the file as ``gatesopt
    solve`` does): the family passed explicitly where the ordering's API takes none. For tests of
    one family's arithmetic on a file that names another (real_cura410_cubic and
    real_prusa240_m486_arcwelder, the classic-jerk examples those tests measured, are sliced
    Marlin-flavoured for Klipper printers: their PRINT_START / print_start macros make them
    Klipper files)."""
    from gatesopt import firmware, limits

    def plan(family: str) -> None:
        firmware.planner_rules(family)      # a family that exists
        monkeypatch.setattr(limits, "default_family", lambda program: (family, f"test: {family} rules"))
    return plan


needs_shared = pytest.mark.skipif(
    not shared_files(), reason=f"development corpus not found at {SHARED_INSTANCES}")


def shared_params():
    """pytest params over the corpus, or one skipped param saying why."""
    files = shared_files()
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(reason=f"no corpus at {SHARED_INSTANCES}"))]
    return [pytest.param(p, id=p.name) for p in files]


def matrix_helper_first(monkeypatch) -> None:
    """The ordering's matrix helper makes every link matrix before the chain's first group (a
    small file's chain would otherwise end before the fresh interpreter starts): the main process
    takes them all (tests/test_greedy_workers.py, tests/test_greedy_work.py)."""
    from gatesopt.ordering import matrix_helper
    start = matrix_helper.MatrixHelper.start.__func__

    def start_and_wait(cls, problem):
        maker = start(cls, problem)
        if maker is not None:
            maker.wait()
        return maker

    monkeypatch.setattr(matrix_helper.MatrixHelper, "start", classmethod(start_and_wait))
