"""What a backend is given and how it answers: jobs, the ``finished`` callback, Dask's address.

A backend takes the submissions still to grade (:class:`Job`) and calls
``finished`` once per submission with its
:class:`~autograder.results.model.SubmissionResult`, after the result's folder is
written (:func:`autograder.results.store.write_submission`).
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Protocol, Sequence
from urllib.parse import urlsplit

from autograder.engine.assignment import Assignment
from autograder.engine.grader import GradingOptions
from autograder.errors import UsageError
from autograder.results.model import SubmissionResult


#: seconds a batch keeps trying to reach a remote scheduler (Dask retries a refused
#: connection until then): a scheduler still starting, or a slow TLS handshake, gets time
CONNECT_SECONDS = 30.0


@dataclass(frozen=True)
class Job:
    """One submission to grade: the file and its id (its folder under the results)."""

    path: Path
    id: str


Finished = Callable[[SubmissionResult], None]


class Backend(Protocol):
    """Grades jobs somewhere; calls ``finished`` exactly once per job, in completion order."""

    def run(self, assignment: Assignment, options: GradingOptions, jobs: Sequence[Job],
            out_dir: Path, finished: Finished) -> None: ...


@dataclass(frozen=True)
class TLSFiles:
    """Certificates for ``tls://`` scheduler addresses (PEM files)."""

    ca_file: Path
    cert: Path
    key: Path | None = None

    def __post_init__(self) -> None:
        for label, path in (("--tls-ca-file", self.ca_file), ("--tls-cert", self.cert),
                            ("--tls-key", self.key)):
            if path is not None and not Path(path).is_file():
                raise UsageError(f"{label} {str(path)!r} is not a file; give the PEM file "
                                 "your cluster's administrator made for this machine.")


@dataclass(frozen=True)
class DaskSpec:
    """How to reach a Dask cluster.

    ``address`` is ``local:N`` (a cluster of N worker processes started on this
    machine for the run), ``tls://host:port`` (with ``tls``), or
    ``tcp://host:port``, which is accepted off loopback only with ``insecure``:
    Dask's control messages are pickled, so whoever can reach the port can run
    code on the client and on every worker.
    """

    address: str
    tls: TLSFiles | None = None
    insecure: bool = False
    #: seconds without any result after which the client says so (it keeps waiting)
    warn_after: float = 300.0
    #: seconds to keep trying to reach the scheduler before giving up (``--dask-connect-timeout``);
    #: None: :data:`CONNECT_SECONDS` for a batch, the service's own (shorter) default for its
    #: dispatcher, which records the job in hand as an "error" result and tries again
    connect_timeout: float | None = None

    def __post_init__(self) -> None:
        check_address(self.address, tls=self.tls, insecure=self.insecure)
        if self.connect_timeout is not None and not self.connect_timeout > 0:
            raise UsageError(f"--dask-connect-timeout {self.connect_timeout}: give a number of "
                             "seconds above 0 (e.g. 30).")

    @property
    def local_workers(self) -> int | None:
        """N for ``local:N``, else None."""
        return local_workers(self.address)


def local_workers(address: str) -> int | None:
    if not address.startswith("local:"):
        return None
    count = address.removeprefix("local:")
    if not count.isdigit() or int(count) < 1:
        raise UsageError(f"--dask {address!r}: write `local:N` with N a whole number of "
                         "workers, at least 1 (e.g. local:2).")
    return int(count)


def check_address(address: str, *, tls: TLSFiles | None, insecure: bool) -> None:
    """Refuse addresses that would expose the cluster; see :class:`DaskSpec`."""
    if local_workers(address) is not None:
        return
    scheme = address.split("://", 1)[0] if "://" in address else "tcp"
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if not parts.hostname or parts.port is None:
        raise UsageError(f"--dask {address!r}: give the scheduler as tls://HOST:PORT "
                         "(or tcp://127.0.0.1:PORT on this machine, or local:N).")
    if scheme == "tls":
        if tls is None:
            raise UsageError(f"--dask {address!r} needs --tls-ca-file and --tls-cert "
                             "(and --tls-key unless the key is in the certificate file).")
        return
    if scheme != "tcp":
        raise UsageError(f"--dask {address!r}: the scheme must be tls:// or tcp://, not {scheme}://.")
    if not insecure and not is_loopback(parts.hostname):
        raise UsageError(
            f"--dask {address!r} is plain tcp:// to another machine. Dask's control messages "
            "are pickled, so anyone who can reach that port can run code on this machine and "
            "on every worker, and read the hidden checks. Use tls:// with --tls-ca-file, "
            "--tls-cert and --tls-key, or pass --insecure on a network only you can reach.")


def is_loopback(host: str) -> bool:
    """Whether every address ``host`` names is a loopback address (no network look-up for IPs)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        pass
    if host == "localhost":
        return True
    try:
        infos = socket.getaddrinfo(host, None)
    except OSError:
        return False
    return bool(infos) and all(ipaddress.ip_address(i[4][0]).is_loopback for i in infos)
