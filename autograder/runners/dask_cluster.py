"""The Dask backend: gradings on the workers of a Dask cluster (``--dask ADDRESS``).

How a grading travels:

* the client packs the assignment as one content-hashed bundle
  (:mod:`autograder.runners.bundle`) and registers :class:`GradingSlots`, a Dask worker
  plugin, under a name holding the bundle's hash. On every worker, now and
  whenever one joins or restarts, the plugin checks the sandbox (in a fresh
  subprocess: a Dask worker is threaded and must not fork) and the engine,
  unpacks the bundle in a private 0700 directory the sandbox never lets student
  code read, and opens one :class:`~autograder.engine.grader.Grader` (its warm worker
  is started with ``subprocess``). A worker that fails a check sets its
  ``grading`` resource to 0, so no grading goes there, and the client says why.
* each task asks for one ``grading`` resource, takes the submission's bytes and
  returns the result as plain data (the ``results.json`` dict and the bytes of
  the files beside it); only the client writes files, atomically, as results
  arrive, so no shared file system is needed.
* a student's time-out or crash is a result, never a task error, so Dask never
  retries a student's infinite loop; a worker that dies mid-grade makes Dask run
  the task elsewhere (``distributed.scheduler.allowed-failures`` times). Dask
  counts a death against every task on the dying worker, so a task that ends as
  ``KilledWorker`` while other gradings were in flight is only a *suspect*: it
  is graded again alone (:func:`killed_worker`); one that kills workers while
  alone gets an ``error`` result, retried on the next run.

:class:`GradingStream` sends gradings with the same pieces one at a time, as
they arrive: the grading service's dispatcher (``autograder serve --dask``).
"""

from __future__ import annotations

import asyncio
import json
import logging
import subprocess
import sys
import threading
import time
import uuid
from collections import deque
from dataclasses import replace
from pathlib import Path, PurePosixPath
from typing import Any, Sequence

import dask.config
import distributed
from distributed import Client, LocalCluster, Nanny, WorkerPlugin, get_worker, wait
from distributed.security import Security

from autograder.engine.assignment import Assignment
from autograder.engine.grader import Grader, GradingOptions, client_key, error_result
from autograder.engine.submission import submission_bytes
from autograder.errors import EngineError, UsageError
from autograder.results.feedback import FEEDBACK_NAME
from autograder.results.files import atomic_write_bytes
from autograder.results.model import SubmissionResult
from autograder.results.store import RESULTS_NAME, write_submission
from autograder.runners.bundle import (
    Bundle,
    engine_fingerprint,
    make_bundle,
    private_directory,
    remove_directory,
)
from autograder.runners.jobs import CONNECT_SECONDS, DaskSpec, Finished, Job, TLSFiles, check_address

log = logging.getLogger("autograder.dask")

#: the Dask resource each grading task asks for; a worker offers one per slot
RESOURCE = "grading"
#: files a payload may not bring (the client writes these itself)
_CLIENT_FILES = frozenset({RESULTS_NAME, FEEDBACK_NAME})
#: seconds between two look-ups of the cluster's grading slots while results arrive
SLOTS_REFRESH = 1.0

#: Dask settings for the processes this module starts (``local:N``'s scheduler, nannies
#: and workers; ``autograder worker``'s nannies and workers). Measured on 2 cores
#: (benchmarks/dask_vs_local.py --cpu): with Dask's defaults an idle worker's event
#: loop used 4-5% of a core and the local scheduler with its nannies 7%, and while a
#: grading ran the statistical profiler walked the grading thread's deep pytest stack
#: 100 times a second on the worker's event loop, holding the GIL the grading needs
#: (~0.15 CPU s per submission). A grading lasts about a second and runs alone on its
#: worker, so none of these earns its cost here:
QUIET_CLUSTER: dict[str, Any] = {
    # the profile shown by the dashboard, sampled every 10 ms
    "distributed.worker.profile.enabled": False,
    # event-loop latency probe, 50 times a second in every server (warnings still come
    # after `distributed.admin.tick.limit`)
    "distributed.admin.tick.interval": "1s",
    # memory, CPU and network figures for the dashboard, twice a second
    "distributed.admin.system-monitor.interval": "2s",
    # each worker's and nanny's memory check; a grading's memory is the sandboxed child's,
    # bounded by its own limit
    "distributed.worker.memory.monitor-interval": "1s",
    # the scheduler moving queued tasks between workers 10 times a second; a task is sent
    # only when a slot is free, so there is never one to move
    "distributed.scheduler.work-stealing": False,
}


def sandbox_notes() -> tuple[str, ...]:
    """This machine's missing protections, probed in a fresh Python process.

    :func:`autograder.sandbox.support.probe_support` forks to try a namespace; a Dask
    worker has threads, so the probe runs in a new interpreter instead.
    """
    code = ("import json; from autograder.sandbox.support import probe_support; "
            "print(json.dumps(list(probe_support().notes)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        raise EngineError("The sandbox could not be probed on this worker: "
                          + (done.stderr.strip().splitlines() or ["no output"])[-1])
    return tuple(json.loads(done.stdout.strip().splitlines()[-1]))


class GradingSlots(WorkerPlugin):
    """Opens one warm grading slot on a Dask worker for one assignment bundle."""

    def __init__(self, bundle: Bundle, options: GradingOptions, fingerprint: str,
                 client_notes: tuple[str, ...]) -> None:
        self.name = f"numgrade-{bundle.digest[:16]}"
        self.bundle = bundle
        self.options = options
        self.fingerprint = fingerprint
        self.client_notes = client_notes
        self.problem = ""
        self._grader: Grader | None = None
        self._home: Path | None = None
        self._top: Path | None = None
        self._lock = threading.Lock()
        self._ready = threading.Event()

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.update(_grader=None, _home=None, _top=None, _lock=None, _ready=None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()
        self._ready = threading.Event()

    async def setup(self, worker: distributed.Worker) -> None:
        try:
            await asyncio.to_thread(self._prepare, Path(worker.local_directory))
        except Exception as exc:  # this worker cannot grade: take it out of the grading pool
            self.problem = f"worker {worker.address} cannot grade: {exc}"
            log.error("%s", self.problem)
            await worker.set_resources(**{RESOURCE: 0})
        finally:
            self._ready.set()  # a task that arrived during the set-up may go on

    def _prepare(self, scratch: Path) -> None:
        if engine_fingerprint() != self.fingerprint:
            raise EngineError("its autograder or reference package differs from the client's; "
                              "install the same version of numgrade on both")
        extra = sorted(set(sandbox_notes()) - set(self.client_notes))
        if extra:
            raise EngineError("its sandbox is weaker than the client's: " + " ".join(extra))
        # Everything under the Dask worker's own directory: Dask deletes it when the worker
        # closes, and also after a worker was killed (the next worker on this machine
        # purges directories whose lock nobody holds), so a killed worker leaves nothing.
        # ``grading`` (bundle, submissions, results) is hidden from the student as a whole;
        # the slot's own home (the warm parent's folder) sits beside it, not inside.
        self._top = private_directory(parent=scratch)
        self._home = self._top / "grading"
        self._home.mkdir(mode=0o700)
        assignment = self.bundle.unpack(self._home / "assignment")
        self._grader = Grader(assignment, self.options, scratch=self._top)

    def teardown(self, worker: distributed.Worker) -> None:
        if self._grader is not None:
            self._grader.close()
            self._grader = None
        if self._top is not None:
            remove_directory(self._top)
            self._top = self._home = None

    def grade(self, data: bytes, filename: str, sub_id: str) -> dict[str, Any]:
        """Grade one submission's bytes; return ``{"result": dict, "files": {path: bytes}}``."""
        self._ready.wait(timeout=600)
        if self._grader is None or self._home is None:
            raise EngineError(self.problem or "the grading slot of this worker is not open")
        with self._lock:  # one grading at a time per slot, whatever the worker's threads
            name = uuid.uuid4().hex
            work = self._home / "work" / name
            # Every result folder in one fixed parent, as in a local batch: the grader hides
            # the parent of ``out`` from the student, and the warm parent caches the sandbox's
            # path lists by that set of hidden folders. A parent of its own per submission
            # made the warm parent recompute them for every grading (~0.4 CPU s each).
            source, out = work / "submission" / Path(filename).name, self._home / "results" / name
            source.parent.mkdir(parents=True, mode=0o700)
            try:
                source.write_bytes(data)
                try:
                    result = self._grader.grade(source, id=sub_id, out_dir=out)
                except (Exception, KeyboardInterrupt) as exc:
                    # The grader's own failure is a result, not a task error. A task thread
                    # never receives Ctrl-C (signals go to the main thread), so an interrupt
                    # here is the engine's "checks run interrupted": never a graded result.
                    result = error_result(self._grader.assignment, source, sub_id, exc)
                files = {p.relative_to(out).as_posix(): p.read_bytes()
                         for p in sorted(out.rglob("*")) if p.is_file()
                         and p.relative_to(out).as_posix() not in _CLIENT_FILES} if out.exists() else {}
                return {"result": result.to_dict(), "files": files}
            finally:
                remove_directory(work)
                remove_directory(out)


def grade_task(plugin_name: str, data: bytes, filename: str, sub_id: str) -> dict[str, Any]:
    """The task run on a worker: find this assignment's slot and grade ``data`` there."""
    plugin = get_worker().plugins.get(plugin_name)
    if not isinstance(plugin, GradingSlots):
        raise EngineError(f"worker {get_worker().address} has no grading slot for this run")
    return plugin.grade(data, filename, sub_id)


def _slot_problem(plugin_name: str, dask_worker: distributed.Worker) -> str:
    """Why this worker refused to grade, or "" (also while its plugin is still being set up)."""
    return getattr(dask_worker.plugins.get(plugin_name), "problem", "")


def security_for(tls: TLSFiles | None, *, role: str = "client") -> Security | None:
    if tls is None:
        return None
    key = str(tls.key) if tls.key is not None else None
    return Security(require_encryption=True, tls_ca_file=str(tls.ca_file),
                    **{f"tls_{role}_cert": str(tls.cert), f"tls_{role}_key": key})


def payload_files(folder: Path, payload: Any, label: str) -> SubmissionResult:
    """Write the files a worker sent beside its result into ``folder``; return the result as sent.

    A name that would leave ``folder`` or replace a file the client writes itself
    is refused (:class:`EngineError`, naming ``label``).
    """
    result = SubmissionResult.from_dict(payload["result"])
    for name, data in payload.get("files", {}).items():
        relative = PurePosixPath(name)
        if relative.is_absolute() or ".." in relative.parts or name in _CLIENT_FILES \
                or not isinstance(data, bytes):
            raise EngineError(f"a worker sent a file named {name!r} for {label}; refused")
        atomic_write_bytes(folder / relative, data)
    return result


def store_payload(out_dir: Path, job: Job, payload: Any, assignment: Assignment, key: str) -> SubmissionResult:
    """Write what a worker sent for ``job``: its files, then ``results.json``, then the feedback page."""
    folder = out_dir / job.id
    result = payload_files(folder, payload, job.id)
    result = replace(result, id=job.id, source=str(job.path),
                     key=key if result.outcome != "error" else "")
    return write_submission(folder, result, title=assignment.title)


def quiet_settings() -> dict[str, Any]:
    """:data:`QUIET_CLUSTER`, less the keys whose value the user changed from Dask's default.

    A value set in a Dask config file or a ``DASK_...`` variable is the user's choice
    and stays in force.
    """
    defaults = dask.config.merge(*dask.config.defaults)
    return {key: value for key, value in QUIET_CLUSTER.items()
            if dask.config.get(key) == dask.config.get(key, config=defaults)}


def local_cluster(workers: int, **options: Any) -> LocalCluster:
    """A cluster of ``workers`` processes on this machine, on loopback, one grading slot each.

    Worker processes are started by Dask's nannies with ``spawn`` (never a fork
    of this threaded process); ``options`` go to :class:`distributed.LocalCluster`.
    The scheduler, the nannies and (through their nannies) the workers take
    :func:`quiet_settings`, read as each starts.
    """
    # dashboard_address=None still starts the scheduler's HTTP server on port 8787, and a
    # second grader on the machine warned that the port was taken: a free loopback port
    # instead, and no dashboard (nobody looks at a run's own cluster).
    settings: dict[str, Any] = dict(n_workers=workers, threads_per_worker=1, processes=True,
                                    host="127.0.0.1", dashboard_address=None,
                                    scheduler_kwargs={"dashboard": False,
                                                      "dashboard_address": "127.0.0.1:0"},
                                    resources={RESOURCE: 1}, silence_logs=logging.ERROR)
    settings.update(options)
    with dask.config.set(quiet_settings()):
        return LocalCluster(**settings)


def connect(spec: DaskSpec, *, timeout: float = CONNECT_SECONDS) -> tuple[LocalCluster | None, Client]:
    """A client of the cluster ``spec`` names; for ``local:N`` also the cluster, started here.

    A remote scheduler is tried for ``spec.connect_timeout`` seconds, else ``timeout``.
    """
    workers = spec.local_workers
    if workers is not None:
        cluster = local_cluster(workers)
        return cluster, Client(cluster)
    wait_for = spec.connect_timeout if spec.connect_timeout is not None else timeout
    try:
        return None, Client(spec.address, security=security_for(spec.tls), timeout=wait_for)
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"Could not reach the Dask scheduler at {spec.address}: {exc}. "
                         "Is it running, and is the address right?") from None


def grading_slots(client: Client) -> int:
    """How many gradings the cluster's workers can run at once now."""
    workers = client.scheduler_info(n_workers=-1)["workers"].values()
    return int(sum(w.get("resources", {}).get(RESOURCE, 0) for w in workers))


def killed_worker(future: Any) -> bool:
    """Whether ``future`` ended as ``KilledWorker``: the workers running it died too often.

    Dask counts a worker's death against *every* task processing on that worker,
    the one it was running and those waiting there (when all workers die at once,
    Dask hands every waiting task to the first worker back). So a ``KilledWorker``
    proves nothing about a task that had other gradings beside it in flight: it
    may have shared a killer's deaths. Such a task is a suspect, graded again
    alone (a new key: Dask's count starts at zero) with nothing else in flight; a
    task that kills workers while alone is the killer. Workers die rarely, so the
    cost, a few gradings run one at a time after a death, is small, and it buys
    the guarantee that one submission that kills workers never costs another its
    result.
    """
    return future.status == "error" and isinstance(future.exception(), distributed.KilledWorker)


class DaskBackend:
    """Grades on a Dask cluster; ``local:N`` starts one of N processes here for the run."""

    def __init__(self, spec: DaskSpec) -> None:
        self.spec = spec

    def _connect(self) -> tuple[LocalCluster | None, Client]:
        return connect(self.spec)

    def run(self, assignment: Assignment, options: GradingOptions, jobs: Sequence[Job],
            out_dir: Path, finished: Finished) -> None:
        from autograder.sandbox.support import probe_support

        cluster, client = self._connect()
        plugin = GradingSlots(make_bundle(assignment), options, engine_fingerprint(),
                              probe_support().notes)
        try:
            client.register_plugin(plugin, name=plugin.name)
            self._say_worker_problems(client, plugin.name)
            self._collect(client, plugin.name, list(jobs), assignment, options, out_dir, finished)
        finally:
            try:
                if cluster is None:  # a shared cluster: close this run's slots on every worker
                    client.unregister_worker_plugin(plugin.name)
            except Exception as exc:  # the run's results are written; say so, do not fail it
                log.warning("could not close the grading slots on the workers: %s", exc)
            client.close()
            if cluster is not None:
                cluster.close()

    @staticmethod
    def _say_worker_problems(client: Client, name: str, *, quiet: bool = False) -> None:
        """Print why workers refused to grade; fail when every connected worker refused."""
        answers = client.run(_slot_problem, name, on_error="return")  # a dying worker is no refusal
        problems = {w: p for w, p in answers.items() if isinstance(p, str) and p}
        for problem in () if quiet else problems.values():
            print(f"autograder: warning: {problem}", file=sys.stderr)
        workers = client.scheduler_info(n_workers=-1)["workers"]
        if workers and len(problems) == len(workers):
            raise EngineError("No Dask worker can grade (results so far are kept; fix the workers "
                              "and run again): " + "; ".join(sorted(set(problems.values()))))
        if not workers and not quiet:
            print("autograder: note: no Dask worker is connected yet; gradings start when one "
                  "joins (autograder worker ADDRESS --slots N).", file=sys.stderr)

    def _collect(self, client: Client, plugin: str, jobs: list[Job], assignment: Assignment,
                 options: GradingOptions, out_dir: Path, finished: Finished) -> None:
        """Keep one task per grading slot in flight; store each result as it arrives.

        Submitting only as many tasks as there are slots (rather than all at once)
        keeps Dask from queueing several gradings on one worker. That is not
        enough when every worker dies at once: Dask then hands the waiting tasks
        to the first worker back, and they share the deaths of whatever runs
        there. So a task that ends as ``KilledWorker`` after other gradings were in
        flight beside it is a suspect (:func:`killed_worker`): once the queue is
        empty and nothing else is in flight, each suspect is graded again alone,
        and only a suspect that kills workers while alone gets an ``error`` result.
        Suspects wait for the end of the queue rather than draining the slots at
        once: the slots stay busy until then, and a drain mid-batch would idle them
        for the same lone gradings.
        """
        queue = deque(jobs)
        running: dict[Any, Job] = {}
        shared: set[Any] = set()  # tasks that had another grading in flight beside them
        suspects: deque[Job] = deque()
        last = time.monotonic()
        capacity, checked = 1, float("-inf")

        def submit(job: Job) -> None:
            future = client.submit(grade_task, plugin, *submission_bytes(job.path), job.id,
                                   key=f"grade-{job.id}-{uuid.uuid4().hex[:8]}",
                                   resources={RESOURCE: 1}, pure=False)
            if running:
                shared.update(running, (future,))
            running[future] = job

        def top_up() -> None:
            nonlocal capacity, checked
            # Asking the scheduler costs a round trip; a worker that joins waits a second.
            if time.monotonic() - checked >= SLOTS_REFRESH:
                capacity, checked = max(1, grading_slots(client)), time.monotonic()
            while queue and len(running) < capacity:
                submit(queue.popleft())
            if not queue and not running and suspects:
                submit(suspects.popleft())  # alone; the next one waits until it is done

        top_up()
        while running:
            try:
                done, _ = wait(list(running), timeout=min(5.0, self.spec.warn_after),
                               return_when="FIRST_COMPLETED")
            except TimeoutError:  # no result yet: new workers may have joined; say so when long
                if grading_slots(client) == 0:
                    self._say_worker_problems(client, plugin, quiet=True)
                if time.monotonic() - last >= self.spec.warn_after:
                    print(f"autograder: warning: no result arrived for {time.monotonic() - last:.0f} s; "
                          f"{len(running) + len(queue) + len(suspects)} submission(s) still to grade "
                          f"on {grading_slots(client)} grading slot(s).", file=sys.stderr)
                    last = time.monotonic()
                top_up()
                continue
            last = time.monotonic()
            finished_jobs = []
            for future in done:
                job = running.pop(future)
                if future in shared and killed_worker(future):
                    log.info("%s lost its workers beside other gradings; it is graded again alone",
                             job.id)
                    suspects.append(job)
                else:
                    finished_jobs.append((future, job))
                shared.discard(future)
            top_up()  # the freed slots grade on while this client writes the results
            for future, job in finished_jobs:
                finished(self._store(future, job, assignment, options, out_dir))

    @staticmethod
    def _store(future: Any, job: Job, assignment: Assignment, options: GradingOptions,
               out_dir: Path) -> SubmissionResult:
        if future.status == "finished":
            try:
                return store_payload(out_dir, job, future.result(), assignment,
                                     client_key(job.path, assignment, options))
            except (KeyError, TypeError, ValueError, EngineError) as exc:
                problem: BaseException | str = exc
        else:
            exc = future.exception()
            problem = (f"the Dask workers grading it stopped ({type(exc).__name__}: {exc})"
                       if isinstance(exc, distributed.KilledWorker) else exc)
        return write_submission(out_dir / job.id, error_result(assignment, job.path, job.id, problem),
                                title=assignment.title)


# ------------------------------------------------------------------ gradings one at a time


def task_payload(future: Any) -> Any:
    """What a finished grading task returned; :class:`EngineError` saying why it returned nothing."""
    if future.status == "finished":
        return future.result()
    if future.status == "error":
        exc = future.exception()
        if isinstance(exc, distributed.KilledWorker):
            raise EngineError(f"the Dask workers grading it stopped ({type(exc).__name__}: {exc})")
        raise EngineError(f"the grading task failed on the Dask cluster ({type(exc).__name__}: {exc})")
    raise EngineError(f"the Dask cluster dropped the grading task (it is {future.status}); "
                      "the scheduler may have gone away")


class GradingStream:
    """Gradings sent one at a time as they arrive (the service's dispatcher), on one client.

    The pieces are the batch's: one :class:`GradingSlots` per assignment bundle
    and options, registered when first needed and again when the bundle changes
    (the slots of the old bundle are closed once nothing graded there is out), and
    :func:`grade_task` asking for one ``grading`` resource. The caller keeps at
    most :meth:`slots` tasks out. The connection is made on first use and made
    again after :meth:`close`; the slots are named apart from a batch run's
    (``numgrade-service-...``), so a batch on the same cluster never closes them.
    """

    def __init__(self, spec: DaskSpec, *, connect_timeout: float = CONNECT_SECONDS) -> None:
        self.spec = spec
        self.connect_timeout = connect_timeout
        self._cluster: LocalCluster | None = None
        self._client: Client | None = None
        self._notes: tuple[str, ...] | None = None
        self._current: dict[tuple[str, str], str] = {}  # (folder, options) -> the newest slots
        self._registered: set[str] = set()

    @property
    def client(self) -> Client:
        if self._client is not None and self._client.status in ("closing", "closed"):
            self.close()
        if self._client is None:
            self._cluster, self._client = connect(self.spec, timeout=self.connect_timeout)
        return self._client

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.status == "running"

    def slots(self) -> int:
        """How many gradings the cluster's workers can run at once now."""
        return grading_slots(self.client)

    def slots_for(self, assignment: Assignment, options: GradingOptions) -> str:
        """The name of the grading slots for this assignment as it is now (registered if new).

        Raises :class:`EngineError` when every connected worker refuses them.
        """
        if self._notes is None:  # probed in a fresh process: this one has the client's threads
            self._notes = sandbox_notes()
        plugin = GradingSlots(make_bundle(assignment), options, engine_fingerprint(), self._notes)
        plugin.name = f"numgrade-service-{plugin.bundle.digest[:16]}-{options.digest()[:8]}"
        self._current[(str(assignment.root), options.digest())] = plugin.name
        if plugin.name not in self._registered:
            self.client.register_plugin(plugin, name=plugin.name)
            self._registered.add(plugin.name)
            DaskBackend._say_worker_problems(self.client, plugin.name)
        return plugin.name

    def submit(self, slots: str, data: bytes, filename: str, sub_id: str) -> Any:
        """Send one grading; the future's :func:`task_payload` is what :func:`store_payload` takes."""
        return self.client.submit(grade_task, slots, data, filename, sub_id,
                                  key=f"grade-{sub_id}-{uuid.uuid4().hex[:8]}",
                                  resources={RESOURCE: 1}, pure=False)

    def finished(self, futures: list[Any], timeout: float) -> list[Any]:
        """The futures among ``futures`` that are done, waiting up to ``timeout`` for the first."""
        try:
            done, _ = wait(futures, timeout=timeout, return_when="FIRST_COMPLETED")
        except TimeoutError:
            return []
        return list(done)

    def refusal(self, slots: str) -> str:
        """Why no connected worker grades with ``slots``, or "" (some can, or none is connected)."""
        try:
            DaskBackend._say_worker_problems(self.client, slots, quiet=True)
        except EngineError as exc:
            return str(exc)
        return ""

    def forget(self, slots: str) -> None:
        """Register ``slots`` anew at its next use (fresh slots after an engine failure)."""
        self._registered.discard(slots)

    def retire_unused(self, in_use: set[str]) -> None:
        """Close the slots of bundles that changed since, once no grading there is out."""
        for name in sorted(self._registered - set(self._current.values()) - in_use):
            self._unregister(name)

    def _unregister(self, name: str) -> None:
        self._registered.discard(name)
        try:
            if self._client is not None:
                self._client.unregister_worker_plugin(name)
        except Exception as exc:  # the worker side closes them with the cluster anyway
            log.warning("could not close the grading slots %s on the workers: %s", name, exc)

    def close(self) -> None:
        """Close this service's slots on a shared cluster, the client, and a ``local:N`` cluster."""
        if self._client is not None and self._cluster is None and self._client.status == "running":
            for name in sorted(self._registered):
                self._unregister(name)
        client, cluster = self._client, self._cluster
        self._client, self._cluster = None, None
        self._registered.clear()
        self._current.clear()
        try:
            if client is not None:
                client.close(timeout=10)
        finally:
            if cluster is not None:
                cluster.close(timeout=30)


# ------------------------------------------------------------------ the worker command


def run_worker(address: str, *, slots: int, tls: TLSFiles | None = None,
               insecure: bool = False) -> None:
    """Run ``slots`` Dask worker processes (one grading slot each) until stopped.

    Each is a Dask ``Nanny`` with one thread and one ``grading`` resource; the
    nanny restarts its worker if it dies, and the client's plugin opens the
    worker's slot again.
    """
    check_address(address, tls=tls, insecure=insecure)
    if address.startswith("local:"):
        raise UsageError("`autograder worker` joins a running scheduler: give its address "
                         "(tls://HOST:PORT, or tcp://127.0.0.1:PORT on this machine).")
    asyncio.run(_serve(address, slots, security_for(tls, role="worker")))


async def _serve(address: str, slots: int, security: Security | None) -> None:
    with dask.config.set(quiet_settings()):  # each nanny hands its config to its worker
        nannies = [Nanny(address, nthreads=1, resources={RESOURCE: 1}, security=security)
                   for _ in range(slots)]
    await asyncio.gather(*(n.start() for n in nannies))
    try:
        await asyncio.gather(*(n.finished() for n in nannies))
    finally:
        await asyncio.gather(*(n.close() for n in nannies), return_exceptions=True)


__all__ = ["QUIET_CLUSTER", "DaskBackend", "GradingSlots", "GradingStream", "connect", "grade_task",
           "killed_worker", "local_cluster", "payload_files", "quiet_settings", "run_worker", "sandbox_notes", "security_for", "store_payload", "task_payload"]
