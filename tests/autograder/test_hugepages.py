"""The warm parent moves its heap into huge pages once a batch is long.

Fewer page-table entries make each ``fork()`` and each child's exit cheaper
(``benchmarks/fork_floor.py``); these tests check that it happens, where the kernel
can do it, and that grading is unchanged.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.worker import hugepages
from tests.support.assignments import CHECK, RIGHT, submission, write_double

PROBE = textwrap.dedent("""
    from autograder.worker import hugepages
    keep = [list(range(50)) for _ in range(40_000)]  # some 20 MiB of small objects
    print(hugepages.collapse(), hugepages.huge_bytes())
""")


def _collapse_in_fresh_process() -> tuple[int, int]:
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         check=True, timeout=120).stdout.split()
    return int(out[0]), int(out[1])


@pytest.fixture(scope="module")
def kernel_collapses() -> None:
    if not sys.platform.startswith("linux"):
        pytest.skip("huge pages by madvise(MADV_COLLAPSE) are a Linux feature")
    collapsed, _ = _collapse_in_fresh_process()
    if collapsed == 0:
        pytest.skip("this kernel does not collapse memory into huge pages "
                    "(MADV_COLLAPSE needs Linux 6.1 and transparent huge pages)")


def _anon_huge_bytes(pid: int) -> int:
    return hugepages.huge_bytes(f"/proc/{pid}/smaps_rollup")


def test_collapse_moves_the_heap_into_huge_pages(kernel_collapses: None) -> None:
    collapsed, huge = _collapse_in_fresh_process()
    assert collapsed >= hugepages.HUGE_PAGE
    assert huge >= hugepages.HUGE_PAGE


def test_collapse_reports_nothing_where_nothing_can_be_read(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-maps"
    assert list(hugepages._private_anonymous_ranges(str(missing))) == []
    assert hugepages.huge_bytes(str(missing)) == 0


def test_only_aligned_parts_of_anonymous_writable_mappings_are_asked_for(tmp_path: Path) -> None:
    maps = tmp_path / "maps"
    maps.write_text(
        "00200000-00a00000 rw-p 00000000 00:00 0 \n"                      # anonymous: 8 MiB
        "00b00000-00c00000 rw-p 00000000 00:00 0 \n"                      # 1 MiB: no huge page
        "01000000-01700000 rw-p 00000000 00:00 0          [heap]\n"       # heap, cut to 6 MiB
        "02000000-02400000 r--p 00000000 00:00 0 \n"                      # not writable
        "03000000-03400000 rw-p 00001000 fe:00 12         /usr/lib/x.so\n"  # a file's data
        "04000000-04400000 rw-p 00000000 00:00 0          [stack]\n")
    assert list(hugepages._private_anonymous_ranges(str(maps))) == [
        (0x00200000, 0x00A00000), (0x01000000, 0x01600000)]


def test_the_warm_parent_collapses_once_a_batch_is_long(
        tmp_path: Path, kernel_collapses: None) -> None:
    folder = write_double(tmp_path, "double", {"test_double.py": CHECK})
    notebook = submission(tmp_path / "in", "s", RIGHT)
    with Grader(load_assignment(folder)) as grader:
        scores = []
        for k in range(hugepages.COLLAPSE_AFTER + 1):
            scores.append(grader.grade(notebook).score)
            parent = grader._slot.warm_parent
            assert parent is not None
            if k == 0:
                before = _anon_huge_bytes(parent)
        # the parent collapsed while child COLLAPSE_AFTER ran, then forked the next one
        after = _anon_huge_bytes(parent)
    assert after >= before + hugepages.HUGE_PAGE
    assert scores == [1.0] * (hugepages.COLLAPSE_AFTER + 1)
