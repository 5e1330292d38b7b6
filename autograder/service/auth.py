"""Sign-in: access tokens (stored hashed), browser sessions with a CSRF token, roster import."""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
import hmac
import io
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from autograder.errors import UsageError
from autograder.service.models import BrowserLogin, User, utcnow

ROLES = ("student", "ta", "instructor")
STAFF = ("ta", "instructor")


TOKEN_PREFIX = "ngt_"


def new_token() -> str:
    """A fresh access token: 192 random bits, URL-safe, after a fixed prefix.

    The prefix keeps a token from starting with ``-``: one in 64 of the bare
    URL-safe strings did, and ``autograder submit --token -x...`` then failed with
    argparse's "expected one argument". It also lets secret scanners spot a leaked
    token in a repository.
    """
    return TOKEN_PREFIX + secrets.token_urlsafe(24)


def token_hash(token: str) -> str:
    """SHA-256 of a token. Tokens are random (not passwords), so no slow hash is needed."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def user_for_token(session: Session, token: str) -> User | None:
    if not token or len(token) > 200:
        return None
    return session.scalars(select(User).where(User.token_hash == token_hash(token))).first()


@dataclass(frozen=True)
class SignedIn:
    """The browser session: who, and the CSRF token its forms must carry."""

    user_id: str
    role: str
    csrf: str


def open_session(session: Session, user: User) -> str:
    """Start a browser session for ``user``; return the cookie value."""
    cookie = secrets.token_urlsafe(32)
    session.add(BrowserLogin(id_hash=token_hash(cookie), user_id=user.id,
                           csrf=secrets.token_urlsafe(24), created_at=utcnow()))
    return cookie


def find_session(session: Session, cookie: str | None, *, lifetime: dt.timedelta,
                 now: dt.datetime | None = None) -> SignedIn | None:
    """The browser session of ``cookie`` if it began less than ``lifetime`` ago."""
    if not cookie or len(cookie) > 200:
        return None
    row = session.get(BrowserLogin, token_hash(cookie))
    if row is None or row.created_at + lifetime <= (now or utcnow()):
        return None  # expired rows are deleted at the next sign-in (end_expired_sessions)
    user = session.get(User, row.user_id)
    return None if user is None else SignedIn(user.id, user.role, row.csrf)


def end_expired_sessions(session: Session, *, lifetime: dt.timedelta,
                         now: dt.datetime | None = None) -> None:
    session.execute(delete(BrowserLogin).where(BrowserLogin.created_at <= (now or utcnow()) - lifetime))


def end_sessions(session: Session, user_ids: Iterable[str]) -> None:
    """Sign every browser of these users out (their tokens changed)."""
    ids = list(user_ids)
    if ids:
        session.execute(delete(BrowserLogin).where(BrowserLogin.user_id.in_(ids)))


def close_session(session: Session, cookie: str | None) -> None:
    if cookie:
        row = session.get(BrowserLogin, token_hash(cookie))
        if row is not None:
            session.delete(row)


def same_secret(given: str | None, expected: str) -> bool:
    return given is not None and hmac.compare_digest(given.encode(), expected.encode())


@dataclass(frozen=True)
class RosterEntry:
    id: str
    name: str
    email: str
    role: str
    canvas_id: str = ""


#: the header of GitHub Classroom's roster download
CLASSROOM_COLUMNS = ("identifier", "github_username", "github_id", "name")


def _roster_text(path: Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise UsageError(f"Cannot read the roster {str(path)!r}: {exc.strerror}.") from None


def is_classroom_roster(fields: Iterable[str] | None) -> bool:
    """True for GitHub Classroom's roster CSV (``identifier, github_username, ...``)."""
    return {"identifier", "github_username"} <= set(fields or ()) and "id" not in set(fields or ())


def unlinked_rows(path: Path) -> tuple[str, ...]:
    """The identifiers of a Classroom roster's rows with no GitHub account linked yet."""
    reader = csv.DictReader(io.StringIO(_roster_text(path)))
    if not is_classroom_roster(reader.fieldnames):
        return ()
    return tuple((row.get("identifier") or "").strip() for row in reader
                 if not (row.get("github_username") or "").strip())


def _from_classroom(rows: Iterable[dict[str, str]]) -> Iterator[dict[str, str]]:
    """Classroom's rows as ours: the GitHub username is the id (the repositories are named
    by it, so grades and uploads meet); an identifier with ``@`` is the email. Rows with no
    account linked are left out (:func:`unlinked_rows` lists them)."""
    for row in rows:
        username = (row.get("github_username") or "").strip()
        identifier = (row.get("identifier") or "").strip()
        if username:
            yield {"id": username, "name": (row.get("name") or "").strip() or identifier,
                   "email": identifier if "@" in identifier else "", "role": "student"}


def read_roster(path: Path) -> list[RosterEntry]:
    """Rows of a roster CSV with columns ``id, name, email`` (and optionally ``role``,
    ``canvas_id``), or
    GitHub Classroom's roster (``identifier, github_username, github_id, name``)."""
    reader = csv.DictReader(io.StringIO(_roster_text(path)))
    if is_classroom_roster(reader.fieldnames):
        return _entries(path, _from_classroom(reader))
    missing = {"id", "name", "email"} - set(reader.fieldnames or ())
    if missing:
        raise UsageError(f"{path}: the roster needs the columns id, name, email (and optionally "
                         f"role), or GitHub Classroom's {', '.join(CLASSROOM_COLUMNS)}; "
                         f"missing {sorted(missing)}.")
    return _entries(path, reader)


def _entries(path: Path, reader: Iterable[dict[str, str]]) -> list[RosterEntry]:
    entries: list[RosterEntry] = []
    for line, row in enumerate(reader, start=2):
        sid = (row.get("id") or "").strip()
        role = (row.get("role") or "student").strip() or "student"
        if not sid or len(sid) > 128:
            raise UsageError(f"{path}, line {line}: every row needs an id (at most 128 characters).")
        if role not in ROLES:
            raise UsageError(f"{path}, line {line}: role must be one of {', '.join(ROLES)}; got {role!r}.")
        canvas_id = (row.get("canvas_id") or "").strip()
        if canvas_id and (not canvas_id.isdigit() or len(canvas_id) > 32):
            raise UsageError(f"{path}, line {line}: canvas_id is Canvas's numeric user id "
                             f"(People > the student > the number in the address); got {canvas_id!r}.")
        entries.append(RosterEntry(sid, (row.get("name") or "").strip(),
                                   (row.get("email") or "").strip(), role, canvas_id))
    ids = [e.id for e in entries]
    if len(set(ids)) != len(ids):
        raise UsageError(f"{path}: ids must be unique in the roster.")
    return entries


@dataclass(frozen=True)
class RosterChanges:
    """What importing a roster did: who was added, who was there already, the new tokens."""

    added: tuple[str, ...]
    already: tuple[str, ...]
    issued: tuple[tuple[User, str], ...]


def import_roster(session: Session, entries: Iterable[RosterEntry]) -> RosterChanges:
    """Add new people (with a token) and update the name, email and role of the others.

    Nobody's token changes: someone already on the roster keeps the token they
    have (only someone without one, such as a person added by hand, gets one).
    """
    issued: list[tuple[User, str]] = []
    added: list[str] = []
    already: list[str] = []
    for entry in entries:
        user = session.get(User, entry.id)
        if user is None:
            user = User(id=entry.id, name=entry.name, email=entry.email, role=entry.role,
                        canvas_id=entry.canvas_id)
            session.add(user)
            added.append(entry.id)
        else:
            user.name, user.email, user.role = entry.name, entry.email, entry.role
            user.canvas_id = entry.canvas_id
            already.append(entry.id)
        if user.token_hash is None:
            token = new_token()
            user.token_hash = token_hash(token)
            issued.append((user, token))
    return RosterChanges(tuple(added), tuple(already), tuple(issued))


def issue_tokens(session: Session, *, everyone: bool) -> list[tuple[User, str]]:
    """New tokens for users without one (or for everyone, which revokes the old ones).

    A new token also signs out every browser its holder had signed in with the
    old one: rotating tokens is how an instructor ends a leaked token's sessions.
    """
    issued: list[tuple[User, str]] = []
    for user in session.scalars(select(User).order_by(User.id)):
        if everyone or user.token_hash is None:
            token = new_token()
            user.token_hash = token_hash(token)
            issued.append((user, token))
    end_sessions(session, (user.id for user, _ in issued))
    return issued


def kept_tokens(session: Session, text: str, *, besides: Iterable[str]) -> list[tuple[User, str]]:
    """Rows of an earlier tokens CSV whose token is still the holder's (not those in ``besides``).

    A token that no longer matches the database (rotated since) is left out: it opens nothing.
    """
    skip = set(besides)
    kept: list[tuple[User, str]] = []
    for row in csv.DictReader(io.StringIO(text)):
        uid, token = (row.get("id") or "").strip(), (row.get("token") or "").strip()
        user = session.get(User, uid) if uid and uid not in skip else None
        if user is not None and token and user.token_hash == token_hash(token):
            kept.append((user, token))
            skip.add(uid)
    return kept


def tokens_csv(issued: Iterable[tuple[User, str]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["id", "name", "email", "role", "token"])
    for user, token in issued:
        writer.writerow([user.id, user.name, user.email, user.role, token])
    return buffer.getvalue()
