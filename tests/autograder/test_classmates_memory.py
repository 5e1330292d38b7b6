"""A submission cannot read the code of the submissions its slot graded before it.

Every child is a copy of its slot's warm parent, freed memory included. A student
who reads their own process's memory (numpy reads any address it is given) finds
whatever the warm parent once decoded; if that were the cells of the submissions
before, their code would be one ``print`` away from this student's feedback. The
cells go to the sandboxed child directly, never through the warm parent.
"""

from __future__ import annotations

import re
import uuid
from pathlib import Path

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from tests.support.assignments import CHECK, RIGHT, submission, write_double

#: what every classmate's cell holds, followed by 32 hex digits of their own
PREFIX = "numgrade-classmate-"

#: reads every readable mapping of its own process and prints the markers it finds;
#: the prefix is built at run time so that this cell's source holds it only where it
#: is followed by this student's own marker (the positive control)
SCANNER = '''
import numpy as np, re
prefix = "-".join(["numgrade", "classmate", ""]).encode()
found = set()
for line in open("/proc/self/maps").read().splitlines():
    fields = line.split()
    low, high = (int(v, 16) for v in fields[0].split("-"))
    name = fields[5] if len(fields) > 5 else ""
    if "r" not in fields[1] or name in ("[vvar]", "[vvar_vclock]", "[vsyscall]") or high - low > 1 << 30:
        continue
    class View:
        __array_interface__ = {"data": (low, True), "shape": (high - low,), "typestr": "|u1",
                               "version": 3}
    try:
        memory = np.asarray(View()).tobytes()
    except Exception:
        continue
    found.update(m.group(1).decode() for m in re.finditer(re.escape(prefix) + b"([0-9a-f]{32})", memory))
print("FOUND", sorted(found))
'''


def test_a_submission_reads_nothing_of_the_ones_graded_before_it(tmp_path: Path) -> None:
    folder = write_double(tmp_path, "dbl", {"test_double.py": CHECK})
    classmates = [uuid.uuid4().hex for _ in range(3)]
    own = uuid.uuid4().hex
    books = tmp_path / "submitted"
    with Grader(load_assignment(folder)) as grader:
        for number, marker in enumerate(classmates):  # small cells: freed, not overwritten
            result = grader.grade(submission(books, f"c{number}", f"# {PREFIX}{marker}\n{RIGHT}"),
                                  id=f"c{number}", out_dir=tmp_path / "out" / f"c{number}")
            assert result.score == result.max_score
        scanner = submission(books, "scanner", f"# {PREFIX}{own}\n{SCANNER}\n{RIGHT}")
        result = grader.grade(scanner, id="scanner", out_dir=tmp_path / "out" / "scanner")
    lines = re.findall(r"FOUND \[.*\]", result.stdout)
    assert lines, f"the scan did not finish: {result.stdout[-2000:]} {result.output[-2000:]}"
    found = set(re.findall(r"[0-9a-f]{32}", lines[0]))
    assert own in found, "the scan did not see this submission's own source in its memory"
    assert found.isdisjoint(classmates), "a classmate's code was in the submission's memory"
    assert result.score == result.max_score
