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
            view = client.get(f"{url}/api/submissions/{sub_id}").json()
            if view["status"] not in ("queued", "running"):
                if view["status"] != "graded":
                    raise RuntimeError(f"submission {sub_id} ended {view['status']}")
                return time.perf_counter() - start
            time.sleep(0.02)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--students", type=int, default=30)
    parser.add_argument("--burst", type=int, default=200)
    parser.add_argument("--database", default=None)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="service-bench-"))
    course = write_course(folder, max(args.students, 30))
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    command = [sys.executable, "-m", "autograder", "serve", str(course), "--port", str(port),
               "--jobs", str(args.jobs)] + (["--database", args.database] if args.database else [])
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        while True:
            try:
                httpx.get(url + "/login", timeout=2)
                break
            except httpx.HTTPError:
                if server.poll() is not None:
                    raise SystemExit("the service did not start")
                time.sleep(0.3)
        with (folder / "data" / "tokens.csv").open() as handle:
            tokens = [row["token"] for row in csv.DictReader(handle)]
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
        # sustained uploads: accepted per second, then graded per second
        headers = [{"Authorization": f"Bearer {t}", "Accept": "application/json"} for t in tokens]
        ids: list[int] = []
        start = time.perf_counter()

        def send(i: int) -> int:
            with httpx.Client(timeout=600, headers=headers[i % len(headers)]) as client:
                answer = client.post(f"{url}/assignments/hull/submissions",
                                     files={"notebook": ("hull.ipynb", SOLUTION + b" " * (i % 50),
                                                         "application/x-ipynb+json")})
                answer.raise_for_status()
                return int(answer.json()["id"])

        with ThreadPoolExecutor(30) as pool:
            ids = list(pool.map(send, range(args.burst)))
        accepted = time.perf_counter() - start
        with ThreadPoolExecutor(30) as pool:
            list(pool.map(lambda i: _wait_owner(url, headers[i % len(headers)], ids[i]), range(len(ids))))
        graded = time.perf_counter() - start
    finally:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
    # the peer: the batch grader on the same notebooks, same number of processes
    batch = folder / "batch"
    batch.mkdir()
    for i in range(args.burst):
        (batch / f"n{i:04d}.ipynb").write_bytes(SOLUTION + b" " * (i % 50))
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", str(batch), "--out",
                    str(folder / "batch-out"), "--jobs", str(args.jobs), "--no-progress"],
                   check=True, stdout=subprocess.DEVNULL)
    peer = time.perf_counter() - start
    shutil.rmtree(folder, ignore_errors=True)
    service_rate, batch_rate = args.burst / graded, args.burst / peer
    print(f"service_latency: hull solution, every check, {args.jobs} grading processes, "
          f"{'SQLite' if not args.database else args.database.split(':')[0]}")
    print(f"  1 student   upload->graded  median {statistics.median(one):.2f} s  "
          f"p95 {percentile(one, 0.95):.2f} s  ({args.rounds} uploads)")
    print(f"  {args.students} students at once         median {statistics.median(many):.2f} s  "
          f"p95 {percentile(many, 0.95):.2f} s")
    print(f"  uploads accepted  {args.burst / accepted:.1f}/s  ({args.burst} uploads, 30 clients)")
    print(f"  graded            {service_rate:.2f}/s  vs batch `autograder grade --jobs {args.jobs}` "
          f"{batch_rate:.2f}/s (start-up included): ratio {service_rate / batch_rate:.2f}")


def _wait_owner(url: str, headers: dict[str, str], sub_id: int) -> None:
    with httpx.Client(timeout=600, headers=headers) as client:
        while client.get(f"{url}/api/submissions/{sub_id}").json()["status"] in ("queued", "running"):
            time.sleep(0.1)


if __name__ == "__main__":
    main()
