"""Upload-to-graded latency and throughput of ``autograder serve`` (not a test: prints figures).

Starts the service on 127.0.0.1 with SQLite (or ``--database URL``) and the
``hull`` assignment with every check, then measures, for a correct hull
notebook:

* 1 student: upload -> graded, median and 95th percentile over ``--rounds`` uploads;
* 30 students uploading at the same moment: the same figures;
* sustained uploads/s the service accepts (``--burst`` uploads from 30 threads);
* its grading rate beside the batch grader's (``autograder grade --jobs N``) on the
  same notebooks in the same run (the peer), as a ratio.

Run: ``python benchmarks/service_latency.py`` (about 3 minutes on 2 idle cores).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
from _record import Figure, add_json_option, record

ROOT = Path(__file__).resolve().parents[1]
SOLUTION = (ROOT / "assignments" / "hull" / "examples" / "solution.ipynb").read_bytes()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def write_course(folder: Path, students: int) -> Path:
    deadline = (dt.datetime.now(dt.timezone.utc) + dt.timedelta(days=30)).strftime("%Y-%m-%dT%H:%M:%SZ")
    (folder / "course.toml").write_text(f"""
[course]
name = "Benchmark"
roster = "roster.csv"
data = "data"
submissions_per_hour = 100000

[[assignment]]
name = "hull"
opens = 2020-01-01T00:00:00Z
deadline = {deadline}
""")
    with (folder / "roster.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["id", "name", "email"])
        writer.writerows((f"s{i:03d}", f"S {i}", f"s{i}@x") for i in range(students))
    return folder / "course.toml"


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q * (len(ordered) - 1))))]


def upload_and_wait(url: str, token: str, data: bytes) -> float:
    headers = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    with httpx.Client(timeout=600, headers=headers) as client:
        start = time.perf_counter()
        answer = client.post(f"{url}/assignments/hull/submissions",
                             files={"notebook": ("hull.ipynb", data, "application/x-ipynb+json")})
        answer.raise_for_status()
        sub_id = answer.json()["id"]
        while True:
            # as `autograder submit` asks: the answer comes once graded (a service without
            # ?wait answers at once, and is asked again every 20 ms)
            asked = time.perf_counter()
            view = client.get(f"{url}/api/submissions/{sub_id}", params={"wait": 30}).json()
            if view["status"] not in ("queued", "running"):
                if view["status"] != "graded":
                    raise RuntimeError(f"submission {sub_id} ended {view['status']}")
                return time.perf_counter() - start
            time.sleep(max(0.0, 0.02 - (time.perf_counter() - asked)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--students", type=int, default=30)
    parser.add_argument("--burst", type=int, default=200)
    parser.add_argument("--database", default=None)
    add_json_option(parser, "service_latency")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="service-bench-"))
    course = write_course(folder, max(args.students, 30))
    url, server = start_service(course, args.jobs, args.database)
    try:
        with (folder / "data" / "tokens.csv").open() as handle:
            tokens = [row["token"] for row in csv.DictReader(handle)]
        one, many = latencies(url, tokens, args)
        accepted, graded = sustained(url, tokens, args.burst)
    finally:
        stop_service(server)
    peer = batch_seconds(folder, args.burst, args.jobs)
    shutil.rmtree(folder, ignore_errors=True)
    report(args, one, many, accepted, graded, peer)


def start_service(course: Path, jobs: int,
                  database: str | None) -> tuple[str, subprocess.Popen[bytes]]:
    """``autograder serve`` on a free port, once it answers; its URL and process."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    command = [sys.executable, "-m", "autograder", "serve", str(course), "--port", str(port),
               "--jobs", str(jobs)] + (["--database", database] if database else [])
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        while True:
            try:
                httpx.get(url + "/login", timeout=2)
                return url, server
            except httpx.HTTPError:
                if server.poll() is not None:
                    raise SystemExit("the service did not start")
                time.sleep(0.3)
    except BaseException:
        stop_service(server)
        raise


def stop_service(server: subprocess.Popen[bytes]) -> None:
    server.send_signal(signal.SIGINT)
    try:
        server.wait(60)
    except subprocess.TimeoutExpired:
        os.killpg(server.pid, signal.SIGKILL)


def latencies(url: str, tokens: list[str],
              args: argparse.Namespace) -> tuple[list[float], list[float]]:
    """Upload-to-graded seconds of one student ``--rounds`` times, then of ``--students``
    at once."""
    # warm every grading process (the first grading in each imports the checks)
    with ThreadPoolExecutor(args.jobs * 2) as pool:
        list(pool.map(lambda t: upload_and_wait(url, t, SOLUTION), tokens[:args.jobs * 2]))
    one = [upload_and_wait(url, tokens[0], SOLUTION) for _ in range(args.rounds)]
    barrier = threading.Barrier(args.students)

    def together(token: str) -> float:
        barrier.wait()
        return upload_and_wait(url, token, SOLUTION)

    with ThreadPoolExecutor(args.students) as pool:
        many = list(pool.map(together, tokens[:args.students]))
    return one, many


def sustained(url: str, tokens: list[str], burst: int) -> tuple[float, float]:
    """Seconds until ``burst`` uploads from 30 clients are accepted, and until all are graded."""
    headers = [{"Authorization": f"Bearer {t}", "Accept": "application/json"} for t in tokens]
    start = time.perf_counter()

    def send(i: int) -> int:
        with httpx.Client(timeout=600, headers=headers[i % len(headers)]) as client:
            answer = client.post(f"{url}/assignments/hull/submissions",
                                 files={"notebook": ("hull.ipynb", SOLUTION + b" " * (i % 50),
                                                     "application/x-ipynb+json")})
            answer.raise_for_status()
            return int(answer.json()["id"])

    with ThreadPoolExecutor(30) as pool:
        ids = list(pool.map(send, range(burst)))
    accepted = time.perf_counter() - start
    with ThreadPoolExecutor(30) as pool:
        list(pool.map(lambda i: _wait_owner(url, headers[i % len(headers)], ids[i]),
                      range(len(ids))))
    return accepted, time.perf_counter() - start


def batch_seconds(folder: Path, burst: int, jobs: int) -> float:
    """The peer: the batch grader on the same notebooks, same number of processes."""
    batch = folder / "batch"
    batch.mkdir()
    for i in range(burst):
        (batch / f"n{i:04d}.ipynb").write_bytes(SOLUTION + b" " * (i % 50))
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", str(batch), "--out",
                    str(folder / "batch-out"), "--jobs", str(jobs), "--no-progress"],
                   check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def report(args: argparse.Namespace, one: list[float], many: list[float], accepted: float,
           graded: float, peer: float) -> None:
    """Print the figures and record them."""
    service_rate, batch_rate = args.burst / graded, args.burst / peer
    database = "SQLite" if not args.database else args.database.split(":")[0]
    print(f"service_latency: hull solution, every check, {args.jobs} grading processes, "
          f"{database}")
    print(f"  1 student   upload->graded  median {statistics.median(one):.2f} s  "
          f"p95 {percentile(one, 0.95):.2f} s  ({args.rounds} uploads)")
    print(f"  {args.students} students at once         median {statistics.median(many):.2f} s  "
          f"p95 {percentile(many, 0.95):.2f} s")
    print(f"  uploads accepted  {args.burst / accepted:.1f}/s  ({args.burst} uploads, 30 clients)")
    print(f"  graded            {service_rate:.2f}/s  vs batch `autograder grade --jobs {args.jobs}` "
          f"{batch_rate:.2f}/s (start-up included): ratio {service_rate / batch_rate:.2f}")
    record("service_latency", [
        Figure("1 student, upload to graded: median", statistics.median(one), "s"),
        Figure("1 student, upload to graded: p95", percentile(one, 0.95), "s"),
        Figure(f"{args.students} students at once: median", statistics.median(many), "s"),
        Figure(f"{args.students} students at once: p95", percentile(many, 0.95), "s"),
        Figure("uploads accepted", args.burst / accepted, "uploads/s"),
        Figure("graded", service_rate, "submissions/s",
               f"batch `autograder grade --jobs {args.jobs}` (start-up included)", batch_rate),
    ], path=args.json, notes=f"hull solution, every check, {args.jobs} grading processes, "
       f"{database}; {args.rounds} uploads by one student, {args.burst} uploads from 30 clients.")


def _wait_owner(url: str, headers: dict[str, str], sub_id: int) -> None:
    with httpx.Client(timeout=600, headers=headers) as client:
        while client.get(f"{url}/api/submissions/{sub_id}",
                         params={"wait": 30}).json()["status"] in ("queued", "running"):
            time.sleep(0.1)


if __name__ == "__main__":
    main()
