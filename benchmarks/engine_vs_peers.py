"""This engine against the bare floor, nbgrader and otter-grader, on the same files, in one run.

Usage: ``python benchmarks/engine_vs_peers.py [--quick] [--count 24] [--trivial 100]
[--otter PATH-TO-otter] [--skip-peers] [--pairs K]``.

What it prints (each figure is one run over the batch, but for ``--pairs``):

* start-up: CPU and wall seconds of ``autograder --help`` and ``--version`` (best of
  three, beside ``python -c pass``), and for every engine run the time from the
  command's start to its first ``results.json``;
* hull, every check and ``--public-only``: the bare floor (``_floor.py``: student
  cells and the same pytest checks in warm processes, no isolation, one process per
  core), this engine ``--jobs 1`` and ``--jobs 2``, ``nbgrader autograde`` (its test
  cells) and ``otter run`` (the same test cells as OK tests), each with
  submissions/s, CPU per submission split into grader and worker, and every ratio;
  whether the floor gave each submission the engine's score (a check the floor could
  not run would fail at once and cost it nothing);
  then the floor's and the engine's CPU per submission beyond start-up, from a
  10-submission batch run beside it, and its ratio to the floor's;
* a trivial assignment (one cell, one check) built in a temporary folder: the
  engine overhead, total CPU per submission minus the floor's, with start-up spread
  over the batch and, from a 10-submission batch run beside it, beyond start-up
  (what one more submission costs, and the rate of a long batch);
* with ``--pairs K``, the two-core speed-up made resolvable: ``K`` alternating rounds of
  ``--jobs 1`` and ``--jobs 2`` over the hull batch with every check (the median of
  the ``K`` ratios of submissions/s, and of the steady rates, first result to last;
  the seconds outside that stretch, start-up and end, and the whole-run ratio they
  would leave even with a perfect 2x steady rate),
  beside the same rounds of the bare floor on one process and on two: what two
  cores give the per-submission work itself on this machine, with no start-up and
  nothing of the engine.

CPU is measured from outside: ``resource.getrusage(RUSAGE_CHILDREN)`` around each
command (every process it reaped) and, for the split and for processes nobody
reaps, psutil samples of the command's process tree every 0.1 s. "Worker" is the
process that ran student code: ``autograder.worker`` (with the forks it reaped)
for this engine, the ipykernel for nbgrader and otter, nothing for the floor.
On a busy machine every figure moves; the ratios, taken in one run, move less.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nbformat
import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import Figure, add_json_option, record  # noqa: E402
from grade_vs_nbgrader import HULL, build_batch  # noqa: E402

PYTHON = sys.executable
HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Run:
    """One command over a batch: seconds, CPU seconds (total and in workers), first result."""

    label: str
    count: int
    wall: float
    cpu: float
    worker_cpu: float
    first_result: float | None = None
    steady_rate: float | None = None
    #: each submission's score, in the batch's order (the floor's; the engine writes files)
    scores: tuple[float, ...] = ()

    @property
    def rate(self) -> float:
        return self.count / self.wall

    @property
    def cpu_ms(self) -> float:
        return 1000 * self.cpu / self.count

    @property
    def worker_ms(self) -> float:
        return 1000 * self.worker_cpu / self.count

    @property
    def grader_ms(self) -> float:
        return self.cpu_ms - self.worker_ms


class TreeSampler(threading.Thread):
    """Samples the CPU of a process tree; remembers each process's last figures."""

    def __init__(self, root: int, worker_marker: str | None, results: Path | None) -> None:
        super().__init__(daemon=True)
        self.root, self.marker, self.results = root, worker_marker, results
        self.own: dict[int, float] = {}       # pid -> its own user + system
        self.reaped: dict[int, float] = {}    # pid of a worker -> its reaped children's CPU
        self.first: float | None = None
        self.stopping = threading.Event()

    def run(self) -> None:
        start = time.perf_counter()
        while not self.stopping.is_set():
            self.sample()
            if self.first is None and self.results is not None and any(
                    self.results.glob("*/results.json")):
                self.first = time.perf_counter() - start
            self.stopping.wait(0.1)

    def sample(self) -> None:
        try:
            procs = [psutil.Process(self.root)]
            procs += procs[0].children(recursive=True)
        except psutil.Error:
            return
        workers: set[int] = set()
        for proc in procs:  # parents come before their children
            try:
                times = proc.cpu_times()
                worker = self.marker is not None and self.marker in " ".join(proc.cmdline())
                parent = proc.ppid()
            except psutil.Error:
                continue
            if worker:
                workers.add(proc.pid)
                if parent in workers:
                    continue  # a fork of a worker: counted in its parent's children_* once reaped
                self.reaped[proc.pid] = times.children_user + times.children_system
            self.own[proc.pid] = times.user + times.system

    def worker_cpu(self) -> float:
        return sum(self.own[p] + self.reaped[p] for p in self.reaped)


def measure(label: str, cmd: list[str], count: int, *, cwd: Path | None = None,
            worker: str | None = None, results: Path | None = None) -> Run:
    """Run ``cmd`` and measure it; exit on failure with its last output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sampler = TreeSampler(proc.pid, worker, results)
    sampler.start()
    out, err = proc.communicate()
    wall = time.perf_counter() - start
    sampler.stopping.set()
    sampler.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{label}: {' '.join(cmd[:4])} ... exited {proc.returncode}:\n"
                         f"{out[-1500:]}\n{err[-3000:]}")
    reaped = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    sampled = sum(sampler.own.values()) + sum(sampler.reaped.values())
    return Run(label, count, wall, max(reaped, sampled), sampler.worker_cpu(),
               sampler.first, _steady_rate(results))


def _steady_rate(results: Path | None) -> float | None:
    """Submissions/s between the first and the last result written (start-up excluded)."""
    if results is None:
        return None
    stamps = sorted(p.stat().st_mtime for p in results.glob("*/results.json"))
    if len(stamps) < 3 or stamps[-1] <= stamps[0]:
        return None
    return (len(stamps) - 1) / (stamps[-1] - stamps[0])


# -- the runs -------------------------------------------------------------------

def run_floor(assignment: Path, notebooks: list[Path], public_only: bool, procs: int = 2) -> Run:
    """The floor on ``procs`` processes, each with its share; only the warm loops are counted.

    Each share is a contiguous run of the batch, so each holds every kind of submission
    alike (the batch cycles through the examples). Every ``procs``-th notebook, as
    before, gave one process the three examples whose checks cost the most (about
    twice the other's loop): two processes looked 1.5x one, not 2x.
    """
    count = len(notebooks)
    shares = [notebooks[k * count // procs:(k + 1) * count // procs] for k in range(procs)]
    reports = floor_reports(assignment, shares, public_only)
    return Run("bare floor", len(notebooks), max(r["wall"] for r in reports),
               sum(r["cpu"] for r in reports), 0.0,
               scores=tuple(score for r in reports for score in r["scores"]))


def compare_scores(section: str, floor: Run, notebooks: list[Path], out: Path) -> list[Figure]:
    """Whether the floor gave each submission the engine's score (``out``: the engine's run).

    The floor is a fair peer only while it does the checks' work as the engine does, and
    the scores are how that shows: a check the floor cannot run (a fixture it lacks)
    fails at once, costs it nothing, and loses its points. One difference is expected
    and said: the engine refuses what the assignment forbids (the student's call
    raises at once), and the floor has no forbidden list.
    """
    differ: list[tuple[str, float, float, bool]] = []
    # strict: a floor that reported fewer scores than it was given notebooks must not
    # pass as agreeing on the ones it left out
    for notebook, floor_score in zip(notebooks, floor.scores, strict=True):
        student = notebook.parent.parent.name  # <id>/<assignment>/<notebook>.ipynb
        result = json.loads((out / student / "results.json").read_text(encoding="utf-8"))
        if abs(result["score"] - floor_score) > 1e-9:
            errors = result.get("extra_data", {}).get("cell_errors", [])
            forbidden = any(e.get("ename") == "NotAllowedError" for e in errors)
            differ.append((student, floor_score, float(result["score"]), forbidden))
    unexplained = [d for d in differ if not d[3]]
    print(f"  scores: the floor and the engine agree on {len(notebooks) - len(differ)} of "
          f"{len(notebooks)} submissions; {len(differ) - len(unexplained)} differ because the "
          "engine refused a forbidden library (the floor has no forbidden list)"
          + (f"; {len(unexplained)} differ otherwise: " + ", ".join(
              f"{s} (floor {f:g}, engine {e:g})" for s, f, e, _ in unexplained[:5])
             if unexplained else ""), flush=True)
    return [Figure(f"{section}: scores, floor and engine agree", len(notebooks) - len(differ),
                   "submissions", "the batch", len(notebooks)),
            Figure(f"{section}: scores that differ, not for a forbidden library",
                   len(unexplained), "submissions")]


def floor_reports(assignment: Path, shares: list[list[Path]], public_only: bool = False,
                  warm: int = 0) -> list[dict[str, Any]]:
    """One ``_floor.py`` process per non-empty share, all at once; their JSON reports.

    ``warm``: the first notebooks of each share run once, unmeasured (``--warm``).
    """
    extra = (["--public-only"] if public_only else []) + (["--warm", str(warm)] if warm else [])
    running = [subprocess.Popen([PYTHON, str(HERE / "_floor.py"), str(assignment), *extra,
                                 *map(str, share)], stdout=subprocess.PIPE, text=True)
               for share in shares if share]
    reports = []
    for proc in running:
        out, _ = proc.communicate()
        if proc.returncode != 0:
            raise SystemExit(f"floor failed: {out[-2000:]}")
        reports.append(json.loads(out.strip().splitlines()[-1]))
    return reports


def run_engine(assignment: Path, batch: Path, out: Path, jobs: int, public_only: bool,
               count: int) -> Run:
    cmd = [PYTHON, "-m", "autograder", "grade", str(assignment), str(batch), "--out", str(out),
           "--jobs", str(jobs), "--no-progress"] + (["--public-only"] if public_only else [])
    return measure(f"autograder --jobs {jobs}", cmd, count, worker="autograder.worker",
                   results=out)


def warm_caches(assignment: Path, notebook: Path, work: Path) -> None:
    """Grade one submission, unmeasured, so every measured run finds the same caches.

    The engine keeps the released template of an instructor notebook on disk (a later
    run skips importing nbgrader, about 0.85 s of CPU). Without this, the first
    measured run of a new notebook paid that once and the short batch beside it did
    not, which put about 9 ms per submission on the trivial assignment's figure
    beyond start-up.
    """
    one = work / f"warm-{assignment.name}"
    one.mkdir()
    if notebook.is_dir():
        shutil.copytree(notebook, one / notebook.name)
    else:
        shutil.copy(notebook, one / notebook.name)
    subprocess.run([PYTHON, "-m", "autograder", "grade", str(assignment), str(one), "--out",
                    str(work / f"warm-{assignment.name}-out"), "--jobs", "1", "--no-progress"],
                   check=True, capture_output=True)


def prepare_nbgrader(batch: Path, course: Path) -> None:
    (course / "source" / "hull").mkdir(parents=True)
    shutil.copy(HULL / "hull.ipynb", course / "source" / "hull" / "hull.ipynb")
    shutil.copytree(HULL / "data", course / "source" / "hull" / "data")
    (course / "nbgrader_config.py").write_text(
        f'c = get_config()\nc.CourseDirectory.course_id = "bench"\n'
        f'c.CourseDirectory.root = {str(course)!r}\n')
    subprocess.run(["nbgrader", "generate_assignment", "hull", "--force"], cwd=course,
                   check=True, capture_output=True)
    for student in sorted(batch.iterdir()):
        target = course / "submitted" / student.name / "hull"
        shutil.copytree(student / "hull", target)
        shutil.copytree(HULL / "data", target / "data")


def run_nbgrader(batch: Path, course: Path, count: int) -> Run:
    prepare_nbgrader(batch, course)
    return measure("nbgrader autograde", ["nbgrader", "autograde", "hull", "--force"], count,
                   cwd=course, worker="ipykernel")


def otter_zip(work: Path, otter: str) -> Path:
    """An otter autograder zip whose OK tests are the notebook's nbgrader test cells."""
    tests = work / "tests"
    tests.mkdir(parents=True)
    book = nbformat.read(HULL / "hull.ipynb", as_version=4)
    for cell in book.cells:
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type == "code" and meta.get("grade") and not meta.get("solution"):
            name = meta["grade_id"]
            test = {"name": name, "points": meta.get("points", 1), "suites": [{
                "cases": [{"code": f">>> exec({cell.source!r})", "hidden": False, "locked": False}],
                "scored": True, "setup": "", "teardown": "", "type": "doctest"}]}
            (tests / f"{name}.py").write_text(f"OK_FORMAT = True\n\ntest = {test!r}\n")
    (work / "data").mkdir()
    shutil.copytree(HULL / "data", work / "data", dirs_exist_ok=True)
    subprocess.run([otter, "generate", "-t", "tests", "--no-requirements", "--no-environment",
                    "--no-config", "-o", "autograder.zip", "data/pins.csv"], cwd=work, check=True,
                   capture_output=True)
    return work / "autograder.zip"


def run_otter(notebooks: list[Path], work: Path, otter: str) -> Run:
    """``otter run`` once per notebook (it grades one submission per command), in a shell loop."""
    archive = otter_zip(work, otter)
    lines = []
    for k, nb in enumerate(notebooks):
        folder = work / f"sub{k:04d}"
        folder.mkdir()
        shutil.copy(nb, folder / "hull.ipynb")
        shutil.copytree(HULL / "data", folder / "data")
        lines.append(f"{otter} run -a {archive} -o {folder} --no-logo {folder / 'hull.ipynb'} "
                     f">> {work / 'otter.log'} 2>&1 || exit 1")
    script = work / "run.sh"
    script.write_text("set -e\n" + "\n".join(lines) + "\n")
    return measure("otter run", ["bash", str(script)], len(notebooks), cwd=work, worker="ipykernel")


def write_trivial(root: Path, count: int) -> tuple[Path, Path]:
    """A one-cell, one-check assignment and ``count`` submissions of it (half of them wrong)."""
    folder = root / "trivial"
    (folder / "checks" / "public").mkdir(parents=True)
    (folder / "checks" / "hidden").mkdir(parents=True)
    (folder / "assignment.toml").write_text(
        '[assignment]\nname = "trivial"\ntitle = "Double it"\nnotebook = "trivial.ipynb"\n')
    solution = nbformat.v4.new_code_cell(
        "### BEGIN SOLUTION\ndef double(x):\n    return 2 * x\n### END SOLUTION",
        metadata={"nbgrader": {"grade_id": "double", "solution": True, "grade": False,
                               "locked": False, "schema_version": 3}})
    book = nbformat.v4.new_notebook(cells=[solution], metadata={
        "kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}})
    nbformat.write(book, folder / "trivial.ipynb")
    (folder / "checks" / "public" / "test_trivial.py").write_text(
        "def test_double(student):\n    assert student.double(21) == 42, 'double(21) must be 42'\n")
    batch = root / "trivial-submitted"
    for k in range(count):
        body = "2 * x" if k % 2 == 0 else "x + x + 1"
        sub = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(
            f"# submission {k}\ndef double(x):\n    return {body}")], metadata=book.metadata)
        target = batch / f"t{k:04d}.ipynb"
        target.parent.mkdir(exist_ok=True)
        nbformat.write(sub, target)
    return folder, batch


# -- start-up --------------------------------------------------------------------

def startup(cmd: list[str], tries: int = 3) -> tuple[float, float]:
    """Best CPU and wall seconds of ``cmd`` over ``tries`` runs."""
    best_cpu = best_wall = float("inf")
    for _ in range(tries):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        best_wall = min(best_wall, wall)
        best_cpu = min(best_cpu, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return best_cpu, best_wall


def print_startup() -> list[Figure]:
    print("start-up (best of 3; CPU s / wall s):")
    figures: list[Figure] = []
    for label, cmd in (("python -c pass", [PYTHON, "-c", "pass"]),
                       ("autograder --help", [PYTHON, "-m", "autograder", "--help"]),
                       ("autograder --version", [PYTHON, "-m", "autograder", "--version"])):
        cpu, wall = startup(cmd)
        print(f"  {label:<24} {cpu:6.3f} CPU s  {wall:6.3f} s")
        peer = ("python -c pass", figures[0].value) if figures else ()
        figures += [Figure(f"start-up, {label}: CPU", cpu, "s", *peer),
                    Figure(f"start-up, {label}: wall", wall, "s")]
    return figures


# -- report ----------------------------------------------------------------------

def print_header(title: str) -> None:
    print(f"\n{title}")
    print(f"  {'':<22} {'subm/s':>8} {'steady/s':>9} {'CPU ms/subm':>12} {'grader':>8} "
          f"{'worker':>8} {'first result':>13}", flush=True)


def print_row(r: Run) -> Run:
    """Print one run as soon as it is measured (a long run may be stopped half-way)."""
    steady = f"{r.steady_rate:9.2f}" if r.steady_rate else f"{'-':>9}"
    first = f"{r.first_result:11.1f} s" if r.first_result is not None else f"{'-':>13}"
    print(f"  {r.label:<22} {r.rate:8.2f} {steady} {r.cpu_ms:12.1f} {r.grader_ms:8.1f} "
          f"{r.worker_ms:8.1f} {first}", flush=True)
    return r


def run_figures(section: str, runs: list[Run]) -> list[Figure]:
    """The printed rows of ``runs`` as figures named ``section: label: column``."""
    found = []
    for r in runs:
        name = f"{section}: {r.label}"
        found += [Figure(f"{name}: submissions/s", r.rate, "submissions/s"),
                  Figure(f"{name}: steady", r.steady_rate, "submissions/s"),
                  Figure(f"{name}: CPU per submission", r.cpu_ms, "ms"),
                  Figure(f"{name}: grader", r.grader_ms, "ms CPU"),
                  Figure(f"{name}: worker", r.worker_ms, "ms CPU"),
                  Figure(f"{name}: first result", r.first_result, "s")]
    return [f for f in found if f.value is not None]


def print_ratios(runs: list[Run], section: str = "") -> list[Figure]:
    """Print every ratio between ``runs`` that means something; return them as figures."""
    figures = []
    by = {r.label: r for r in runs}
    pairs = [("autograder --jobs 1", "bare floor"), ("autograder --jobs 2", "bare floor"),
             ("autograder --jobs 2", "autograder --jobs 1"),
             ("autograder --jobs 2", "nbgrader autograde"), ("autograder --jobs 2", "otter run"),
             ("autograder --jobs 1", "nbgrader autograde"), ("autograder --jobs 1", "otter run"),
             ("bare floor", "nbgrader autograde"), ("bare floor", "otter run")]
    for a, b in pairs:
        if a in by and b in by:
            print(f"  ratio {a} / {b}: {by[a].rate / by[b].rate:6.2f}x submissions/s, "
                  f"{by[a].cpu_ms / by[b].cpu_ms:6.2f}x CPU per submission", flush=True)
            figures += [Figure(f"{section}: {a}: submissions/s", by[a].rate, "submissions/s",
                               b, by[b].rate),
                        Figure(f"{section}: {a}: CPU per submission", by[a].cpu_ms, "ms", b,
                               by[b].cpu_ms)]
    return figures


#: submissions of the short trivial batch, whose figures are taken off the long one's
SHORT = 10


def trivial_overhead(work: Path, count: int) -> list[Figure]:
    """The engine overhead: CPU per submission of a one-cell, one-check assignment minus the floor's.

    Printed twice: with start-up spread over the batch (the rows), and per
    submission beyond start-up, from a short batch of :data:`SHORT` run beside the
    long one (its CPU and seconds taken off the long batch's: what one more
    submission costs, and the rate at which a long batch goes).
    """
    folder, batch = write_trivial(work, count)
    notebooks = sorted(batch.glob("*.ipynb"))
    short = work / "trivial-short"
    short.mkdir()
    for path in notebooks[:SHORT]:
        shutil.copy(path, short / path.name)
    section = f"trivial, {count} submissions"
    print_header(f"trivial assignment (one cell, one check), {count} submissions")
    floor = print_row(run_floor(folder, notebooks, False))
    warm_caches(folder, notebooks[0], work)
    engine = [print_row(run_engine(folder, batch, work / f"tout-{j}", j, False, count))
              for j in (1, 2)]
    figures = run_figures(section, [floor, *engine]) + print_ratios([floor, *engine], section)
    for r in engine:
        print(f"  engine overhead, {r.label}: {r.cpu_ms - floor.cpu_ms:.1f} ms CPU per "
              f"submission, start-up included (total {r.cpu_ms:.1f} - floor {floor.cpu_ms:.1f})",
              flush=True)
        figures.append(Figure(f"{section}: engine overhead, {r.label}, start-up included",
                              r.cpu_ms - floor.cpu_ms, "ms CPU"))
    if count <= SHORT:
        return figures
    return figures + beyond_startup(section, folder, notebooks, short, engine, floor, False,
                                    work / "tout-short")


def beyond_startup(section: str, assignment: Path, notebooks: list[Path], short: Path,
                   engine: list[Run], floor: Run, public_only: bool, out: Path) -> list[Figure]:
    """CPU per submission beyond start-up: the long runs minus runs over the :data:`SHORT`
    submissions in ``short`` (its CPU and seconds taken off the long batch's: what one
    more submission costs, and the rate at which a long batch goes)."""
    count = len(notebooks)
    extra = count - SHORT
    floor_short = run_floor(assignment, notebooks[:SHORT], public_only)
    floor_ms = 1000 * (floor.cpu - floor_short.cpu) / extra
    print(f"  beyond start-up (the {count}-submission runs minus {SHORT}-submission runs):")
    print(f"    bare floor: {floor_ms:.1f} ms CPU per submission")
    beyond = f"{section}, beyond start-up"
    figures = [Figure(f"{beyond}: bare floor", floor_ms, "ms CPU")]
    for long in engine:
        jobs = int(long.label.rsplit(" ", 1)[1])
        cut = run_engine(assignment, short, Path(f"{out}-{jobs}"), jobs, public_only, SHORT)
        cpu_ms = 1000 * (long.cpu - cut.cpu) / extra
        worker_ms = 1000 * (long.worker_cpu - cut.worker_cpu) / extra
        rate = extra / (long.wall - cut.wall)
        print(f"    {long.label}: {cpu_ms:.1f} ms CPU per submission (grader "
              f"{cpu_ms - worker_ms:.1f}, worker {worker_ms:.1f}), {rate:.1f} submissions/s; "
              f"engine overhead {cpu_ms - floor_ms:.1f} ms, {cpu_ms / floor_ms:.2f}x the floor",
              flush=True)
        figures += [Figure(f"{beyond}: {long.label}: CPU per submission", cpu_ms, "ms",
                           "bare floor", floor_ms),
                    Figure(f"{beyond}: {long.label}: worker", worker_ms, "ms CPU"),
                    Figure(f"{beyond}: {long.label}: rate", rate, "submissions/s")]
    return figures


def jobs_pairs(batch: Path, notebooks: list[Path], work: Path, rounds: int) -> list[Figure]:
    """``rounds`` alternating rounds of ``--jobs 1``, ``--jobs 2`` and the floor on one and
    two processes (hull, every check); the median of each ratio, two cores over one.

    One run of each moves by about 5% between sittings on a shared machine; the median
    of alternated pairs is a figure that a change of that size can move. The floor's
    ratio is the peer: its loops time the per-submission work alone (no imports, no
    start-up, nothing written), so it is what two cores give that work here.
    """
    count = len(notebooks)
    print_header(f"hull, {count} submissions, every check: {rounds} alternating rounds, "
                 "two cores against one")
    ratios: dict[str, list[float]] = {"rate": [], "steady": [], "floor": [], "ceiling": []}
    firsts: list[float] = []
    serial: dict[int, list[float]] = {1: [], 2: []}
    for k in range(rounds):
        one = print_row(run_engine(HULL, batch, work / f"pair-{k}-1", 1, False, count))
        two = print_row(run_engine(HULL, batch, work / f"pair-{k}-2", 2, False, count))
        floor_one = run_floor(HULL, notebooks, False, procs=1)
        floor_two = run_floor(HULL, notebooks, False, procs=2)
        ratios["rate"].append(two.rate / one.rate)
        steady = ""
        if one.steady_rate and two.steady_rate:
            ratios["steady"].append(two.steady_rate / one.steady_rate)
            steady = f", steady {ratios['steady'][-1]:.3f}x"
            # The part of each run outside its steady stretch (first result to last): the
            # start-up before the first result and the end after the last, which one slot
            # or two pay alike. With them, even a perfect 2x steady rate gives the whole
            # run less than 2x: that bound is the ceiling printed beside the ratio.
            for jobs, run in ((1, one), (2, two)):
                serial[jobs].append(run.wall - (count - 1) / run.steady_rate)
            ratios["ceiling"].append(one.wall / (serial[2][-1] + (one.wall - serial[1][-1]) / 2))
            steady += (f"; start-up and end {serial[1][-1]:.2f} s / {serial[2][-1]:.2f} s, "
                       f"so a perfect 2x steady rate would give {ratios['ceiling'][-1]:.3f}x")
        ratios["floor"].append(floor_two.rate / floor_one.rate)
        if two.first_result is not None:
            firsts.append(two.first_result)
        print(f"  round {k + 1}: --jobs 2 / --jobs 1 {ratios['rate'][-1]:.3f}x submissions/s"
              f"{steady}; bare floor, 2 processes / 1: {ratios['floor'][-1]:.3f}x", flush=True)
    section = f"hull, every check, {rounds} alternating rounds"
    figures = []
    for key, label in (("rate", "--jobs 2 / --jobs 1, submissions/s"),
                       ("steady", "--jobs 2 / --jobs 1, steady rate"),
                       ("floor", "bare floor, 2 processes / 1, submissions/s"),
                       ("ceiling", "--jobs 2 / --jobs 1 with a perfect 2x steady rate "
                                   "(the same start-up and end)")):
        if ratios[key]:
            middle = statistics.median(ratios[key])
            spread = f"{min(ratios[key]):.3f}-{max(ratios[key]):.3f}"
            print(f"  median {label}: {middle:.3f}x (range {spread})", flush=True)
            figures += [Figure(f"{section}: {label}: median", middle, "x"),
                        Figure(f"{section}: {label}: lowest", min(ratios[key]), "x"),
                        Figure(f"{section}: {label}: highest", max(ratios[key]), "x")]
    if firsts:
        figures.append(Figure(f"{section}: --jobs 2: first result, median",
                              statistics.median(firsts), "s"))
    for jobs, seconds in serial.items():
        if seconds:
            print(f"  median start-up and end (outside first result to last), --jobs {jobs}: "
                  f"{statistics.median(seconds):.2f} s", flush=True)
            figures.append(Figure(f"{section}: --jobs {jobs}: start-up and end, median",
                                  statistics.median(seconds), "s"))
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="12 hull and 40 trivial submissions")
    parser.add_argument("--count", type=int, default=24, help="hull submissions (default: 24)")
    parser.add_argument("--trivial", type=int, default=100,
                        help="trivial submissions (default: 100; 0 skips the trivial assignment)")
    parser.add_argument("--otter", default=shutil.which("otter"),
                        help="the otter command (e.g. a throwaway venv's bin/otter)")
    parser.add_argument("--otter-count", type=int, default=6,
                        help="hull submissions for otter, the first of the batch (one `otter run` "
                             "each, several seconds apiece; default: 6)")
    parser.add_argument("--skip-peers", action="store_true", help="no nbgrader, no otter")
    parser.add_argument("--pairs", type=int, default=0, metavar="K",
                        help="K alternating rounds of --jobs 1 and --jobs 2 (and the floor on "
                             "one and two processes), every check: the median ratios "
                             "(default: 0, none)")
    add_json_option(parser, "engine_vs_peers")
    args = parser.parse_args(argv)
    count, trivial = (12, min(40, args.trivial)) if args.quick else (args.count, args.trivial)
    if args.quick:
        args.otter_count = min(args.otter_count, 3)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    figures = print_startup()
    with tempfile.TemporaryDirectory(prefix="bench-peers-") as tmp:
        work = Path(tmp)
        if trivial:
            figures += trivial_overhead(work, trivial)
        figures += hull_runs(args, work, count)
    peers = "no peers" if args.skip_peers else \
        f"nbgrader and otter ({args.otter_count} submissions)" if args.otter else "nbgrader"
    record("engine_vs_peers", figures, path=args.json,
           notes=f"{count} hull submissions, {trivial} trivial ones; {peers}. CPU measured "
           "from outside (reaped children and psutil samples of each command's tree).")
    return 0


def hull_runs(args: argparse.Namespace, work: Path, count: int) -> list[Figure]:
    """The hull batch, every check and the public checks: floor, engine and peers."""
    batch = work / "submitted"
    notebooks = build_batch(batch, count)
    short = work / "submitted-short"  # the first SHORT submissions, for beyond start-up
    short.mkdir()
    for student in sorted(batch.iterdir())[:SHORT]:
        shutil.copytree(student, short / student.name)
    peers: list[Run] = []
    figures: list[Figure] = []
    warm_caches(HULL, sorted(batch.iterdir())[0], work)
    for public_only in (False, True):
        print_header(f"hull, {count} submissions, "
                     f"{'public checks only' if public_only else 'every check'} "
                     "(peers: the notebook's own test cells)")
        runs = [print_row(run_floor(HULL, notebooks, public_only))]
        for jobs in (1, 2):
            runs.append(print_row(run_engine(HULL, batch, work / f"out-{jobs}-{public_only}",
                                             jobs, public_only, count)))
        if not args.skip_peers and not public_only:
            peers.append(print_row(run_nbgrader(batch, work / "course", count)))
            if args.otter:
                peers.append(print_row(run_otter(notebooks[:args.otter_count], work / "otter",
                                                 args.otter)))
            else:
                print("otter: not found; pass --otter PATH (pip install otter-grader in a venv)")
        elif peers:  # the peers run their test cells only: the same runs for both lines
            print("  (nbgrader and otter: the runs above)")
        section = f"hull, {'public checks' if public_only else 'every check'}"
        figures += compare_scores(section, runs[0], notebooks, work / f"out-1-{public_only}")
        figures += run_figures(section, runs if public_only else runs + peers)
        figures += print_ratios(runs + peers, section)
        if count > SHORT:
            figures += beyond_startup(section, HULL, notebooks, short, runs[1:3], runs[0],
                                      public_only, work / f"out-short-{public_only}")
    if args.pairs:
        figures += jobs_pairs(batch, notebooks, work, args.pairs)
    return figures


if __name__ == "__main__":
    sys.exit(main())
