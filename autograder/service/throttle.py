"""The sign-in throttle: after too many wrong access tokens from one address, that address waits.

Counted per client address (an IPv6 address by its /64, which one machine
usually holds whole) in a fixed window, in the database, so every service
process sees the same count. A token names no account until it is right, so
there is no per-account count to keep for a wrong one; what is throttled is the
address guessing. A right token does not clear the count (an attacker who is
also a student would otherwise reset it with their own token between guesses),
and while an address is locked even a right token from it waits: the answer
must not tell a guess that hit from one that missed.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import math

from sqlalchemy import delete, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from autograder.service.models import SignInFailure, utcnow
from autograder.service.settings import SIGN_IN_FAILURES, SIGN_IN_WINDOW_MINUTES

WINDOW = dt.timedelta(minutes=SIGN_IN_WINDOW_MINUTES)


def client_key(host: str | None) -> str:
    """The throttled unit of a client address: the address itself, an IPv6 address's /64."""
    try:
        address = ipaddress.ip_address(host or "")
    except ValueError:
        return (host or "unknown")[:64]
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return str(address.ipv4_mapped)
        return str(ipaddress.ip_network(f"{address}/64", strict=False))
    return str(address)


def wait_seconds(session: Session, client: str, now: dt.datetime | None = None) -> int:
    """Seconds ``client`` must still wait before trying a token again (0: it may try now)."""
    now = now or utcnow()
    until = session.scalar(select(SignInFailure.locked_until).where(SignInFailure.client == client))
    if until is None or until <= now:
        return 0
    return max(1, math.ceil((until - now).total_seconds()))


def record_failure(session: Session, client: str, now: dt.datetime | None = None, *,
                   limit: int = SIGN_IN_FAILURES) -> int:
    """Count a wrong token from ``client``; return the seconds it must now wait (0: none yet).

    The ``limit``-th failure in a window locks the address until the window ends.
    """
    now = now or utcnow()
    row = _row(session, client, now)
    if now - row.window_start >= WINDOW:
        row.failures, row.window_start, row.locked_until = 0, now, None
    row.failures += 1
    if row.failures >= limit:
        row.locked_until = row.window_start + WINDOW
    # windows that ended and locks that ran out are of no use: forget them
    session.execute(delete(SignInFailure).where(
        SignInFailure.window_start < now - WINDOW, SignInFailure.client != client,
        (SignInFailure.locked_until.is_(None)) | (SignInFailure.locked_until < now)))
    return wait_seconds(session, client, now) if row.locked_until else 0


def _row(session: Session, client: str, now: dt.datetime) -> SignInFailure:
    """The client's row, locked for this transaction; made when there is none."""
    query = select(SignInFailure).where(SignInFailure.client == client).with_for_update()
    row = session.scalars(query).first()
    if row is not None:
        return row
    try:
        with session.begin_nested():  # another service process may make it at the same moment
            row = SignInFailure(client=client, failures=0, window_start=now)
            session.add(row)
        return row
    except IntegrityError:
        return session.scalars(query).one()
