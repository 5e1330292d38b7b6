"""The LTI tables: the tool's key, launch state, LMS accounts, launch links and the score outbox.

They share :class:`~autograder.service.models.Base` with the rest of the service;
the schema is made by the migration ``0003_lti``. Times are naive UTC.
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import DateTime, Float, ForeignKey, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from autograder.service.models import Base, utcnow


class LtiKey(Base):
    """The tool's RSA key pair, made at first start; its public half is served at /lti/jwks."""

    __tablename__ = "lti_keys"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kid: Mapped[str] = mapped_column(String(64))
    private_pem: Mapped[str] = mapped_column(Text)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class LtiState(Base):
    """What PyLTI1p3 keeps between the login and the launch (state, nonce, launch data)."""

    __tablename__ = "lti_state"
    key: Mapped[str] = mapped_column(String(255), primary_key=True)
    value: Mapped[str] = mapped_column(Text)
    expires_at: Mapped[dt.datetime] = mapped_column(DateTime, index=True)


class LtiAccount(Base):
    """An LMS user (issuer and ``sub``) and the roster entry they sign in as."""

    __tablename__ = "lti_accounts"
    issuer: Mapped[str] = mapped_column(String(255), primary_key=True)
    sub: Mapped[str] = mapped_column(String(255), primary_key=True)
    user_id: Mapped[str] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)


class LtiLink(Base):
    """A line item of an LMS course that a student's score on an assignment goes to."""

    __tablename__ = "lti_links"
    __table_args__ = (UniqueConstraint("user_id", "assignment", "lineitem", name="uq_lti_links"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    user_id: Mapped[str] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    assignment: Mapped[str] = mapped_column(String(128), index=True)
    issuer: Mapped[str] = mapped_column(String(255))
    client_id: Mapped[str] = mapped_column(String(255))
    sub: Mapped[str] = mapped_column(String(255))
    lineitem: Mapped[str] = mapped_column(String(1000))


class LtiScore(Base):
    """The outbox: a score to post to a link's line item, kept until the LMS accepted it."""

    __tablename__ = "lti_scores"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    link_id: Mapped[int] = mapped_column(ForeignKey("lti_links.id", ondelete="CASCADE"), index=True)
    state: Mapped[str] = mapped_column(String(16), default="pending", index=True)  # pending | sent
    tries: Mapped[int] = mapped_column(Integer, default=0)
    next_try_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)
    sent_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    score_given: Mapped[float | None] = mapped_column(Float, nullable=True)
    score_maximum: Mapped[float | None] = mapped_column(Float, nullable=True)
    last_error: Mapped[str] = mapped_column(Text, default="")
