"""Write one benchmark run's figures as JSON, with the machine, the commit, the date and the load.

Every script in ``benchmarks/`` prints its figures as before and, at its end, calls
:func:`record` with the same figures; ``benchmarks/report.py`` turns the files in
``benchmarks/results/`` into ``docs/performance.md``. A script adds the ``--json PATH``
option with :func:`add_json_option` (default ``benchmarks/results/<name>.json``).

The load average at the start is read when this module is imported, so a script
imports it before its own work begins.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, Sequence

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
#: version of the file's layout, for report.py
SCHEMA = 1
#: files whose changes do not make the tree dirty: the results a run of another benchmark wrote
NOT_CODE = "benchmarks/results"


def _load() -> tuple[float, float, float]:
    one, five, fifteen = os.getloadavg()
    return round(one, 2), round(five, 2), round(fifteen, 2)


@dataclass(frozen=True)
class Start:
    """When the run began and the machine's load average then (1, 5 and 15 minutes)."""

    date: str
    clock: float
    load: tuple[float, float, float]

    @classmethod
    def now(cls) -> "Start":
        return cls(dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
                   time.perf_counter(), _load())


#: this run's start: the moment the script imported this module
STARTED = Start.now()


@dataclass(frozen=True)
class Figure:
    """One printed figure: ``value`` in ``unit``; with a peer, the peer's figure and the
    ratio value / peer value (pick value and peer so that it is the ratio printed)."""

    label: str
    value: float | int | bool
    unit: str
    peer: str | None = None
    peer_value: float | None = None

    @property
    def ratio(self) -> float | None:
        if self.peer_value is None or not self.peer_value:
            return None
        return float(self.value) / self.peer_value

    def to_dict(self) -> dict[str, Any]:
        found: dict[str, Any] = {"label": self.label, "value": _rounded(self.value),
                                 "unit": self.unit}
        if self.peer is not None:
            found["peer"] = self.peer
            found["peer_value"] = _rounded(self.peer_value)
            found["ratio"] = _rounded(self.ratio)
        return found


def add_json_option(parser: argparse.ArgumentParser, name: str) -> None:
    """``--json PATH``: where :func:`record` writes (default ``benchmarks/results/<name>.json``)."""
    parser.add_argument("--json", type=Path, default=RESULTS / f"{name}.json", metavar="PATH",
                        help="write the figures, the machine, the commit and the load there "
                        f"(default: benchmarks/results/{name}.json)")


def record(name: str, figures: Sequence[Figure], *, notes: str = "",
           path: Path | None = None) -> Path:
    """Write ``figures`` of the benchmark ``name`` with everything needed to read them later.

    Parameters
    ----------
    name
        The benchmark, as its script is named (``fork_floor``).
    figures
        What the script printed, one :class:`Figure` per figure.
    notes
        What a reader needs to know about this run (counts, the assignment, a caveat).
    path
        Where to write; default ``benchmarks/results/<name>.json``.
    """
    target = Path(path) if path is not None else RESULTS / f"{name}.json"
    document = {
        "schema": SCHEMA,
        "name": name,
        "date": STARTED.date,
        "seconds": round(time.perf_counter() - STARTED.clock, 1),
        "command": command_line(),
        "commit": commit(),
        "machine": {**machine(), "load_average_start": list(STARTED.load),
                    "load_average_end": list(_load())},
        "notes": notes,
        "figures": [figure.to_dict() for figure in figures],
    }
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    shown = target.relative_to(ROOT) if target.resolve().is_relative_to(ROOT) else target
    print(f"(figures written to {shown})")
    return target


def command_line() -> str:
    """The command as typed from the checkout's root: ``python benchmarks/x.py --count 10``."""
    script = Path(sys.argv[0]).resolve() if sys.argv and sys.argv[0] else None
    first = str(script.relative_to(ROOT)) if script and script.is_relative_to(ROOT) \
        else (sys.argv[0] if sys.argv else "")
    return shlex.join(["python", first, *sys.argv[1:]])


def commit() -> dict[str, Any]:
    """The checkout's commit and whether its code differs from it (results files aside)."""
    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True,
                                  text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return done.stdout if done.returncode == 0 else None

    sha = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--", ".", f":(exclude){NOT_CODE}")
    return {"sha": sha.strip() if sha else None,
            "dirty": None if status is None else bool(status.strip())}


def machine() -> dict[str, Any]:
    """CPU model, cores, memory, kernel and the versions the figures depend on."""
    return {"cpu": _cpu_model(), "cores": os.cpu_count(), "memory_gib": _memory_gib(),
            "kernel": f"{platform.system()} {platform.release()}",
            "python": platform.python_version(),
            "numpy": _version("numpy"), "scipy": _version("scipy")}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / (1 << 20), 1)  # kB
    except (OSError, ValueError, IndexError):
        pass
    return None


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def _rounded(value: float | int | bool | None) -> float | int | bool | None:
    """Six significant digits (enough for any figure here, and diffs in git stay readable);
    None for a figure that could not be taken."""
    if value is None or isinstance(value, (bool, int)):
        return value
    if not math.isfinite(value):
        return None  # not measured (JSON has no NaN)
    return float(f"{value:.6g}")
