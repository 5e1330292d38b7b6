"""LMS people as roster entries: LTI roles to the service's roles, accounts, the NRPS roster.

An LMS user is known by the issuer and their ``sub``; the first launch (or the
roster from the course's memberships) makes them a roster entry, named by the
LMS's SIS id when it sends one (so it matches a roster imported from the same
SIS), else by ``sub``. Adding people never touches anyone's access token.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from sqlalchemy import select
from sqlalchemy.orm import Session

from autograder.service.lti.tables import LtiAccount
from autograder.service.models import User

_MEMBERSHIP = "http://purl.imsglobal.org/vocab/lis/v2/membership"
_INSTRUCTOR = {f"{_MEMBERSHIP}#Instructor", f"{_MEMBERSHIP}#Administrator",
               "http://purl.imsglobal.org/vocab/lis/v2/institution/person#Administrator",
               "Instructor", "Administrator"}


def service_role(roles: Iterable[str]) -> str:
    """``ta`` for a teaching assistant, ``instructor`` for an instructor, else ``student``.

    The teaching-assistant sub-role comes first: an LMS may send it beside ``#Instructor``.
    """
    roles = list(roles)
    if any(r.endswith("#TeachingAssistant") or r == "TeachingAssistant" for r in roles):
        return "ta"
    if any(r in _INSTRUCTOR for r in roles):
        return "instructor"
    return "student"


@dataclass(frozen=True)
class Person:
    """What the LMS says about someone (a launch's claims or an NRPS member)."""

    sub: str
    role: str
    name: str = ""
    email: str = ""
    sis_id: str = ""


def person_from_launch(claims: Mapping[str, Any]) -> Person:
    lis = claims.get("https://purl.imsglobal.org/spec/lti/claim/lis") or {}
    return Person(sub=str(claims.get("sub", "")),
                  role=service_role(claims.get("https://purl.imsglobal.org/spec/lti/claim/roles", [])),
                  name=str(claims.get("name", "")), email=str(claims.get("email", "")),
                  sis_id=str(lis.get("person_sourcedid", "") or ""))


def person_from_member(member: Mapping[str, Any]) -> Person:
    return Person(sub=str(member.get("user_id", "")), role=service_role(member.get("roles", [])),
                  name=str(member.get("name", "")), email=str(member.get("email", "")),
                  sis_id=str(member.get("lis_person_sourcedid", "") or ""))


def account_user(session: Session, issuer: str, person: Person) -> User:
    """The roster entry of ``person`` (made, or found and updated); its token is left alone."""
    account = session.get(LtiAccount, (issuer, person.sub))
    user = session.get(User, account.user_id) if account is not None else None
    if user is None:
        wanted = (person.sis_id or person.sub)[:100]
        user = session.get(User, wanted)
        taken = user is not None and session.scalars(
            select(LtiAccount).where(LtiAccount.user_id == wanted)).first() is not None
        if user is None or taken:
            if taken:
                tag = hashlib.sha256(f"{issuer}\n{person.sub}".encode()).hexdigest()[:8]
                wanted = f"{wanted}-{tag}"
            user = session.get(User, wanted) or User(id=wanted)
            session.add(user)
        session.merge(LtiAccount(issuer=issuer, sub=person.sub, user_id=user.id))
    user.role = person.role
    user.name = person.name or user.name or ""
    user.email = person.email or user.email or ""
    return user


def import_members(session: Session, issuer: str, members: Iterable[Mapping[str, Any]]
                   ) -> tuple[int, int]:
    """Add the active members of an LMS course; ``(added, already there)``."""
    added = already = 0
    for member in members:
        if member.get("status", "Active") != "Active" or not member.get("user_id"):
            continue
        known = session.get(LtiAccount, (issuer, str(member["user_id"]))) is not None
        account_user(session, issuer, person_from_member(member))
        session.flush()
        already, added = already + known, added + (not known)
    return added, already
