"""The Dask backend, end to end on one machine: same grades as the local pool,
workers dying mid-grade, reruns, late workers, TLS, and the scheduler out of
students' reach.

Every cluster here is a ``LocalCluster`` of at most two worker processes on
loopback; the checks run public-only to keep the tests short.
"""

from __future__ import annotations

import datetime
import json
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import nbformat
import pytest

distributed = pytest.importorskip("distributed", reason="the Dask backend needs `pip install numgrade[dask]`")

import cloudpickle  # noqa: E402  (installed with distributed)
import dask  # noqa: E402

import dask_test_plugins  # noqa: E402
from autograder import api  # noqa: E402
from autograder.runners.jobs import DaskSpec  # noqa: E402
from autograder.runners.jobs import TLSFiles  # noqa: E402
from autograder.runners.dask_cluster import RESOURCE, local_cluster  # noqa: E402
from autograder.errors import UsageError  # noqa: E402
from autograder.engine.grader import GradingOptions  # noqa: E402
from autograder.results.store import read_result  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "assignments" / "hull" / "examples"
PROBLEMS = ROOT / "tests" / "files" / "problems"
OPTIONS = GradingOptions(public_only=True)

cloudpickle.register_pickle_by_value(dask_test_plugins)


def _notebook(path: Path, *cells: str) -> Path:
    """The problem folder's solution with ``cells`` run first."""
    nb = nbformat.read(PROBLEMS / "solution.ipynb", as_version=4)
    nb.cells[0:0] = [nbformat.v4.new_code_cell(c) for c in cells]
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, path)
    return path


#: a cell that looks for every listening TCP port it can see (its own namespace's,
#: and its ancestors', i.e. the Dask worker's and, for local:N, the scheduler's) and
#: tries to connect to each; it prints what it found and what it reached.
SCAN = '''
import os, socket
ports = set(EXTRA_PORTS)
def listening(path):
    try:
        rows = open(path).read().splitlines()[1:]
    except OSError:
        return set()
    return {int(r.split()[1].rsplit(':', 1)[1], 16) for r in rows if r.split()[3] == '0A'}
pid = os.getpid()
for _ in range(8):
    ports |= listening(f'/proc/{pid}/net/tcp')
    try:
        pid = int(open(f'/proc/{pid}/stat').read().rsplit(')', 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        break
    if pid <= 1:
        break
reached = []
for port in sorted(ports)[:300]:
    try:  # creating the socket itself fails where the sandbox forbids new sockets
        with socket.socket() as s:
            s.settimeout(1.0)
            s.connect(('127.0.0.1', port))
            reached.append(port)
    except OSError:
        pass
print('SCANNED', sorted(ports), 'REACHED', reached)
'''


def _scan_notebook(path: Path, extra_ports: list[int]) -> Path:
    return _notebook(path, f"EXTRA_PORTS = {extra_ports!r}\n" + SCAN)


def _scan_report(stdout: str) -> tuple[list[int], list[int]]:
    line = next((l for l in stdout.splitlines() if l.startswith("SCANNED")), None)
    assert line is not None, f"the scanning cell printed no report; its output was:\n{stdout[-3000:]}"
    scanned, reached = line.removeprefix("SCANNED ").split(" REACHED ")
    return eval(scanned), eval(reached)  # noqa: S307 (our own notebook's printout of two int lists)


@pytest.fixture(scope="module")
def submissions(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("submitted")
    picked = [EXAMPLES / "solution.ipynb", EXAMPLES / "wrong-clockwise.ipynb",
              EXAMPLES / "partial-only-orientation.ipynb", PROBLEMS / "cell-raises.ipynb",
              PROBLEMS / "no-code.ipynb", PROBLEMS / "not-json.ipynb"]
    for path in picked:
        shutil.copy(path, folder / path.name)
    return sorted(folder.iterdir())


def test_dask_gives_the_grades_of_the_local_pool(submissions: list[Path], tmp_path: Path) -> None:
    local = api.grade("hull", submissions, out=tmp_path / "local", jobs=2, options=OPTIONS,
                      progress=False)
    remote = api.grade("hull", submissions, out=tmp_path / "dask", dask="local:2", options=OPTIONS,
                       progress=False)
    assert not local.failed and not remote.failed, [r.output for r in local.failed + remote.failed]
    assert (tmp_path / "dask" / "grades.csv").read_text() == (tmp_path / "local" / "grades.csv").read_text()
    untimed = [{k: v for k, v in json.loads((tmp_path / name / "summary.json").read_text()).items()
                if "seconds" not in k} for name in ("dask", "local")]
    assert untimed[0] == untimed[1]
    for result in remote.results:  # the client wrote every file, with its own paths and keys
        assert (tmp_path / "dask" / result.id / "feedback.html").is_file()
        assert result.source.startswith(str(submissions[0].parent))
        assert read_result(tmp_path / "dask" / result.id).key == read_result(tmp_path / "local" / result.id).key
    # the results folder of one backend is reused by the other: same keys
    again = api.grade("hull", submissions, out=tmp_path / "local", dask="local:2", options=OPTIONS,
                      progress=False)
    assert again.graded == 0 and again.reused == len(submissions)


def test_dead_workers_cost_no_result_and_reruns_send_only_what_is_missing(tmp_path: Path) -> None:
    subs = tmp_path / "subs"
    _notebook(subs / "sleepy.ipynb", "import time\ntime.sleep(1)")  # killed 0.5 s into it
    _notebook(subs / "doomed.ipynb")
    shutil.copy(EXAMPLES / "solution.ipynb", subs / "solution.ipynb")
    marks = tmp_path / "marks"
    marks.mkdir()
    out = tmp_path / "out"
    # One death allowed per task: `sleepy`, killed once by design, is run again by Dask,
    # or, when it also shared a death of `doomed` (Dask counts a death against every
    # task on the worker), graded again alone by the client; `doomed` kills its worker
    # twice beside the others, then twice alone, and becomes an error.
    # The workers' own directories in a folder of the test's: a killed worker's slot and
    # bundle must go with it (Dask purges a dead worker's directory).
    scratch = tmp_path / "scratch"
    with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                          "temporary-directory": str(scratch)}):
        cluster = local_cluster(2)
    with cluster, distributed.Client(cluster) as client:
        client.register_plugin(dask_test_plugins.KillWhenGrading(marks, once=("sleepy",),
                                                                  always=("doomed",)))
        seen: list[str] = []
        report = api.grade("hull", [subs], out=out, dask=cluster.scheduler_address, options=OPTIONS,
                           progress=False, on_result=lambda r: seen.append(r.id))
        assert (marks / "sleepy").exists(), "the worker grading `sleepy` was never killed"
        assert sorted(seen) == ["doomed", "sleepy", "solution"]  # exactly one result each
        by_id = {r.id: r for r in report.results}
        assert by_id["sleepy"].outcome == "graded" and by_id["sleepy"].score == by_id["sleepy"].max_score
        assert by_id["doomed"].outcome == "error" and "regraded on the next run" in by_id["doomed"].output
        assert [r.id for r in report.failed] == ["doomed"]
        assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["doomed", "sleepy", "solution"]
        assert len(list(out.rglob("results.json"))) == 3
        assert not list(out.rglob("*.tmp"))
        assert (out / "grades.csv").read_text().count("\n") == 4

        shutil.rmtree(out / "solution")
        seen.clear()
        rerun = api.grade("hull", [subs], out=out, dask=cluster.scheduler_address, options=OPTIONS,
                          progress=False, on_result=lambda r: seen.append(r.id))
        assert rerun.reused == 1 and sorted(seen) == ["doomed", "solution"]  # error results are retried
    # A killed worker's directory (its bundle and slot inside) is purged by the next worker
    # that starts on the machine, as here: Dask's own rule for directories nobody locks.
    from distributed.diskutils import WorkSpace
    WorkSpace(str(scratch / "dask-scratch-space")).new_work_dir(prefix="next-worker-").release()
    assert [p.name for p in scratch.rglob("autograder-*")] == [], "a slot or bundle outlived its worker"
    assert list(scratch.rglob("worker-*")) == []
    code = subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", str(subs / "doomed.ipynb"),
                           "--out", str(tmp_path / "cli"), "--dask", "tcp://127.0.0.1:9", "--no-progress",
                           "--dask-connect-timeout", "1"],
                          capture_output=True, text=True)
    assert code.returncode == 2 and "Could not reach the Dask scheduler" in code.stderr


def test_a_grading_that_shared_a_killers_death_is_graded_again_alone(tmp_path: Path) -> None:
    """Two gradings in flight on one worker: `doomed` kills it while `innocent` waits there.

    Dask counts that death against both, and with no death allowed both end as
    ``KilledWorker``. Neither is final: each is graded again alone, where only
    `doomed` kills its worker again and gets the error result.
    """
    subs = tmp_path / "subs"
    _notebook(subs / "doomed.ipynb")
    shutil.copy(EXAMPLES / "solution.ipynb", subs / "innocent.ipynb")
    marks = tmp_path / "marks"
    marks.mkdir()
    seen: list[str] = []
    with dask_test_plugins.shared_death_cluster(marks, killer="doomed", witness="innocent") as address:
        report = api.grade("hull", [subs], out=tmp_path / "out", dask=address, options=OPTIONS,
                           progress=False, on_result=lambda r: seen.append(r.id))
    assert (marks / "doomed.shared").exists(), "`doomed` never killed the worker `innocent` was on"
    assert sorted(seen) == ["doomed", "innocent"]  # exactly one result each
    by_id = {r.id: r for r in report.results}
    assert by_id["innocent"].outcome == "graded", by_id["innocent"].output
    assert by_id["innocent"].score == by_id["innocent"].max_score > 0
    assert by_id["doomed"].outcome == "error" and "regraded on the next run" in by_id["doomed"].output
    assert [r.id for r in report.failed] == ["doomed"]


def _certificates(folder: Path) -> TLSFiles:
    """A CA and a certificate for 127.0.0.1 signed by it, made with `cryptography`."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    import ipaddress

    now = datetime.datetime.now(datetime.timezone.utc)
    ca_key, key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "numgrade test CA")])
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name)
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now - datetime.timedelta(days=1)).not_valid_after(now + datetime.timedelta(days=2))
          .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
          .sign(ca_key, hashes.SHA256()))
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "localhost")]))
            .issuer_name(ca_name).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(days=1)).not_valid_after(now + datetime.timedelta(days=2))
            .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost"),
                                                        x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                           critical=False)
            .sign(ca_key, hashes.SHA256()))
    pem = serialization.Encoding.PEM
    (folder / "ca.pem").write_bytes(ca.public_bytes(pem))
    (folder / "cert.pem").write_bytes(cert.public_bytes(pem))
    (folder / "key.pem").write_bytes(key.private_bytes(pem, serialization.PrivateFormat.PKCS8,
                                                       serialization.NoEncryption()))
    return TLSFiles(ca_file=folder / "ca.pem", cert=folder / "cert.pem", key=folder / "key.pem")


def test_tls_cluster_a_late_worker_and_a_scheduler_students_cannot_reach(tmp_path: Path) -> None:
    pytest.importorskip("cryptography", reason="making test certificates needs `cryptography`")
    tls = _certificates(tmp_path)
    security = distributed.security.Security(
        require_encryption=True, tls_ca_file=str(tls.ca_file),
        **{f"tls_{role}_{part}": str(getattr(tls, "cert" if part == "cert" else "key"))
           for role in ("scheduler", "worker", "client") for part in ("cert", "key")})
    with local_cluster(0, protocol="tls://", security=security) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        port = int(address.rsplit(":", 1)[1])
        notebook = _scan_notebook(tmp_path / "subs" / "scan.ipynb", [port])
        outcome: dict[str, object] = {}

        def grade() -> None:
            try:
                outcome["report"] = api.grade("hull", [notebook], out=tmp_path / "out", options=OPTIONS,
                                              dask=DaskSpec(address, tls=tls), progress=False)
            except BaseException as exc:  # reported by the assertion below
                outcome["error"] = exc

        thread = threading.Thread(target=grade)
        thread.start()
        thread.join(timeout=2)  # the batch waits: no worker has a grading slot yet
        assert thread.is_alive() and not outcome
        cluster.scale(1)  # a worker joining after the start gets its slot from the plugin
        thread.join(timeout=800)
        assert not thread.is_alive() and "error" not in outcome, outcome
    result = outcome["report"].results[0]  # type: ignore[attr-defined]
    assert result.outcome == "graded" and result.score == result.max_score
    scanned, reached = _scan_report(result.stdout)
    assert port in scanned and reached == []


def test_scheduler_of_local_cluster_is_out_of_reach(tmp_path: Path) -> None:
    notebook = _scan_notebook(tmp_path / "subs" / "scan.ipynb", [])
    report = api.grade("hull", [notebook], out=tmp_path / "out", dask="local:2", options=OPTIONS,
                       progress=False)
    result = report.results[0]
    assert result.outcome == "graded" and result.score == result.max_score
    scanned, reached = _scan_report(result.stdout)
    assert reached == [], f"student code reached ports {reached} (of {scanned})"


def test_two_local_clusters_at_once_share_no_port() -> None:
    """Another grader's `--dask local:N` on the machine: no port taken from the other, no
    "Port 8787 is already in use" warning, and the scheduler's HTTP server on loopback only."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with local_cluster(1) as first, local_cluster(1) as second:
            bound = [sock.getsockname() for c in (first, second)
                     for sock in c.scheduler.http_server._sockets.values()]
            links = [first.dashboard_link, second.dashboard_link]
    assert not [str(w.message) for w in caught if "already in use" in str(w.message)]
    assert {host for host, _ in bound} == {"127.0.0.1"} and 8787 not in {port for _, port in bound}
    assert len({port for _, port in bound}) == 2, links


@pytest.mark.parametrize("address", ["tcp://10.1.2.3:8786", "192.0.2.7:8786", "tcp://[2001:db8::1]:8786"])
def test_plain_tcp_off_loopback_is_refused_without_insecure(address: str, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="pickled"):
        DaskSpec(address)
    assert DaskSpec(address, insecure=True).address == address
    done = subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", str(EXAMPLES / "solution.ipynb"),
                           "--out", str(tmp_path / "out"), "--dask", address],
                          capture_output=True, text=True)
    assert done.returncode == 2 and "--insecure" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "out" / "solution").exists()


def test_addresses_on_loopback_and_tls_are_accepted(tmp_path: Path) -> None:
    assert DaskSpec("tcp://127.0.0.1:8786").local_workers is None
    assert DaskSpec("local:3").local_workers == 3
    with pytest.raises(UsageError, match="local:N"):
        DaskSpec("local:zero")
    assert DaskSpec("tcp://127.0.0.1:8786", connect_timeout=1.5).connect_timeout == 1.5
    with pytest.raises(UsageError, match="--dask-connect-timeout"):
        DaskSpec("tcp://127.0.0.1:8786", connect_timeout=0)
    with pytest.raises(UsageError, match="--tls-ca-file"):
        DaskSpec("tls://grader.example.edu:8786")
    with pytest.raises(UsageError, match="is not a file"):
        TLSFiles(ca_file=tmp_path / "missing.pem", cert=tmp_path / "missing.pem")


def test_worker_command_serves_grading_slots(tmp_path: Path) -> None:
    import signal

    with local_cluster(0) as cluster:
        node = subprocess.Popen([sys.executable, "-m", "autograder", "worker", cluster.scheduler_address,
                                 "--slots", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            report = api.grade("hull", [EXAMPLES / "solution.ipynb"], out=tmp_path / "out",
                               dask=cluster.scheduler_address, options=OPTIONS, progress=False)
            workers = cluster.scheduler.workers.values()
            assert [w.resources for w in workers] == [{RESOURCE: 1}]
        finally:
            node.send_signal(signal.SIGINT)
            try:
                node.communicate(timeout=120)
            except subprocess.TimeoutExpired:
                node.kill()
                node.communicate()
    result = report.results[0]
    assert result.outcome == "graded" and result.score == result.max_score
