"""The course file (TOML): assignments, dates, late policy, limits, sign-in settings.

Read once at start-up into frozen dataclasses; every bad value is reported with
the file, the table and the key it came from.
"""

from __future__ import annotations

import datetime as dt
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from autograder.errors import UsageError
from autograder.service.settings import SESSION_HOURS

Counting = Literal["last", "best"]
DAY = dt.timedelta(days=1)


@dataclass(frozen=True)
class AssignmentPolicy:
    """One assignment of the course and the rules for submitting it."""

    name: str
    spec: str  # a shipped assignment name or a folder path, as load_assignment takes it
    title: str
    opens: dt.datetime  # UTC, naive (the database stores naive UTC)
    deadline: dt.datetime
    late_penalty_per_day: float = 0.0
    max_late_days: int = 0
    count: Counting = "best"
    public_only: bool = False
    extensions: tuple[tuple[str, dt.datetime], ...] = ()

    def deadline_for(self, student: str, override: dt.datetime | None = None) -> dt.datetime:
        """The student's deadline: an extension from the database, else from the file, else the class's."""
        if override is not None:
            return override
        return dict(self.extensions).get(student, self.deadline)

    def closes_for(self, deadline: dt.datetime) -> dt.datetime:
        """When uploads stop being accepted for someone whose deadline is ``deadline``."""
        return deadline + self.max_late_days * DAY

    def late_days(self, submitted: dt.datetime, deadline: dt.datetime) -> int:
        """Whole days late, each started day counted (0 when on time)."""
        if submitted <= deadline:
            return 0
        return math.ceil((submitted - deadline) / DAY)

    def penalty(self, late_days: int) -> float:
        """The fraction taken off the score for ``late_days`` days late (at most 1)."""
        return min(1.0, late_days * self.late_penalty_per_day)


@dataclass(frozen=True)
class Course:
    """Everything the course file says."""

    path: Path
    name: str
    assignments: tuple[AssignmentPolicy, ...]
    database_url: str
    data_dir: Path
    roster: Path | None = None
    submissions_per_hour: int = 20
    max_upload_bytes: int = 5 * 1024 * 1024
    trusted_header: str | None = None
    trusted_proxies: tuple[str, ...] = ("127.0.0.1", "::1")
    max_tries: int = 3
    #: how long a browser session lasts after sign-in
    session_lifetime: dt.timedelta = dt.timedelta(hours=SESSION_HOURS)
    extra: dict[str, Any] = field(default_factory=dict, compare=False)
    #: the LMS registrations this service is an LTI 1.3 tool of (``[[lti.platforms]]``)
    lti_platforms: tuple["LtiPlatform", ...] = ()

    def assignment(self, name: str) -> AssignmentPolicy | None:
        return next((a for a in self.assignments if a.name == name), None)


_COURSE_KEYS = {"name", "roster", "database", "data", "submissions_per_hour", "max_upload_bytes",
                "timezone", "max_tries"}
_AUTH_KEYS = {"trusted_header", "trusted_proxies", "session_hours"}
_ASSIGNMENT_KEYS = {"name", "assignment", "title", "opens", "deadline", "late_penalty_per_day",
                    "max_late_days", "count", "public_only", "extensions"}


def load_course(path: str | Path) -> Course:
    """Read and check a course file; raise :class:`UsageError` naming any bad value."""
    path = Path(path).resolve()
    if not path.is_file():
        raise UsageError(f"The course file {str(path)!r} does not exist; pass the path of a "
                         "course TOML file (see examples/course/course.toml).")
    try:
        config = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from None
    unknown = set(config) - {"course", "auth", "assignment", "lti"}
    if unknown:
        raise UsageError(f"{path}: unknown table(s) {sorted(unknown)}; expected [course], "
                         "[auth], [[assignment]] and [[lti.platforms]].")
    course = _table(path, config, "course", _COURSE_KEYS)
    auth = _table(path, config, "auth", _AUTH_KEYS)
    zone = _zone(path, course.get("timezone", "UTC"))
    items = config.get("assignment", [])
    if not isinstance(items, list) or not items:
        raise UsageError(f"{path}: name at least one assignment in an [[assignment]] table.")
    assignments = tuple(_assignment(path, i, item, zone) for i, item in enumerate(items))
    names = [a.name for a in assignments]
    if len(set(names)) != len(names):
        raise UsageError(f"{path}: assignment names must be unique; got {names}.")
    stem = path.stem
    data_dir = _relative(path, course.get("data", f"{stem}-data"))
    database = course.get("database") or f"sqlite:///{data_dir / (stem + '.sqlite3')}"
    roster = course.get("roster")
    return Course(
        path=path, name=str(course.get("name", stem)), assignments=assignments,
        database_url=str(database), data_dir=data_dir,
        roster=_relative(path, roster) if roster else None,
        submissions_per_hour=_positive(path, "course", "submissions_per_hour",
                                       course.get("submissions_per_hour", 20)),
        max_upload_bytes=_positive(path, "course", "max_upload_bytes",
                                   course.get("max_upload_bytes", 5 * 1024 * 1024)),
        max_tries=_positive(path, "course", "max_tries", course.get("max_tries", 3)),
        trusted_header=auth.get("trusted_header") or None,
        trusted_proxies=tuple(auth.get("trusted_proxies", ("127.0.0.1", "::1"))),
        session_lifetime=_hours(path, "auth", "session_hours", auth.get("session_hours", SESSION_HOURS)),
        lti_platforms=_lti_platforms(path, config.get("lti", {})),
    )


@dataclass(frozen=True)
class LtiPlatform:
    """One LMS registration of the tool (PyLTI1p3's names); see docs/lti.md."""

    issuer: str
    client_id: str
    deployment_ids: tuple[str, ...]
    auth_login_url: str
    auth_token_url: str
    key_set_url: str


_LTI_KEYS = ("issuer", "client_id", "deployment_ids", "auth_login_url", "auth_token_url",
             "key_set_url")


def _lti_platforms(path: Path, lti: Any) -> tuple[LtiPlatform, ...]:
    """``[[lti.platforms]]``: every key required, deployment ids a non-empty list of strings."""
    if not isinstance(lti, dict) or set(lti) - {"platforms"}:
        raise UsageError(f"{path}: [lti] holds only [[lti.platforms]] tables.")
    platforms = []
    for i, item in enumerate(lti.get("platforms", [])):
        where = f"[[lti.platforms]] #{i + 1}"
        if not isinstance(item, dict) or set(item) != set(_LTI_KEYS):
            raise UsageError(f"{path}: {where} needs exactly the keys {', '.join(_LTI_KEYS)}"
                             + (f"; unknown or missing: {sorted(set(item) ^ set(_LTI_KEYS))}."
                                if isinstance(item, dict) else "."))
        ids = item["deployment_ids"]
        if not isinstance(ids, list) or not ids or not all(isinstance(d, str) and d for d in ids):
            raise UsageError(f"{path}: {where} deployment_ids must be a list of the LMS's "
                             f"deployment ids (strings); got {ids!r}.")
        for key in _LTI_KEYS[:2] + _LTI_KEYS[3:]:
            if not isinstance(item[key], str) or not item[key]:
                raise UsageError(f"{path}: {where} {key} must be a non-empty string.")
        platforms.append(LtiPlatform(item["issuer"], item["client_id"], tuple(ids),
                                     item["auth_login_url"], item["auth_token_url"],
                                     item["key_set_url"]))
    pairs = [(p.issuer, p.client_id) for p in platforms]
    if len(set(pairs)) != len(pairs):
        raise UsageError(f"{path}: two [[lti.platforms]] have the same issuer and client_id.")
    return tuple(platforms)


def _table(path: Path, config: dict[str, Any], name: str, keys: set[str]) -> dict[str, Any]:
    table = config.get(name, {})
    if not isinstance(table, dict):
        raise UsageError(f"{path}: [{name}] must be a table.")
    unknown = set(table) - keys
    if unknown:
        raise UsageError(f"{path}: unknown key(s) {sorted(unknown)} in [{name}]; "
                         f"known keys: {sorted(keys)}.")
    return table


def _zone(path: Path, name: Any) -> ZoneInfo:
    try:
        return ZoneInfo(str(name))
    except (ZoneInfoNotFoundError, ValueError):
        raise UsageError(f"{path}: [course] timezone {name!r} is not a known time zone "
                         "(write e.g. \"Europe/Berlin\" or \"UTC\").") from None


def _relative(path: Path, value: Any) -> Path:
    target = Path(str(value)).expanduser()
    return target if target.is_absolute() else (path.parent / target).resolve()


def _positive(path: Path, table: str, key: str, value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise UsageError(f"{path}: [{table}] {key} must be a whole number >= 1; got {value!r}.")
    return value


def _hours(path: Path, table: str, key: str, value: Any) -> dt.timedelta:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not 0 < value <= 24 * 366:
        raise UsageError(f"{path}: [{table}] {key} must be a number of hours above 0 (12 is "
                         f"half a day, 0.5 half an hour); got {value!r}.")
    return dt.timedelta(hours=value)


def _when(path: Path, where: str, value: Any, zone: ZoneInfo) -> dt.datetime:
    """A TOML date-time as naive UTC; a time without offset is read in the course's zone."""
    if isinstance(value, str):
        try:
            value = dt.datetime.fromisoformat(value)
        except ValueError:
            value = None
    if not isinstance(value, dt.datetime):
        raise UsageError(f"{path}: {where} must be a date-time such as 2026-10-01T23:59:00+02:00; "
                         f"got {value!r}.")
    if value.tzinfo is None:
        value = value.replace(tzinfo=zone)
    return value.astimezone(dt.timezone.utc).replace(tzinfo=None)


def _assignment(path: Path, index: int, item: Any, zone: ZoneInfo) -> AssignmentPolicy:
    where = f"[[assignment]] #{index + 1}"
    if not isinstance(item, dict):
        raise UsageError(f"{path}: {where} must be a table.")
    unknown = set(item) - _ASSIGNMENT_KEYS
    if unknown:
        raise UsageError(f"{path}: unknown key(s) {sorted(unknown)} in {where}; "
                         f"known keys: {sorted(_ASSIGNMENT_KEYS)}.")
    name = item.get("name")
    if not isinstance(name, str) or not name.isidentifier():
        raise UsageError(f"{path}: {where} needs name = \"...\" (letters, digits, underscores); "
                         f"got {name!r}.")
    where = f"[[assignment]] {name!r}"
    spec = str(item.get("assignment", name))
    if "/" in spec or spec.startswith("."):
        spec = str(_relative(path, spec))
    for key in ("opens", "deadline"):
        if key not in item:
            raise UsageError(f"{path}: {where} needs {key} = <date-time>.")
    opens = _when(path, f"{where} opens", item["opens"], zone)
    deadline = _when(path, f"{where} deadline", item["deadline"], zone)
    if deadline <= opens:
        raise UsageError(f"{path}: {where} deadline must come after opens.")
    per_day = item.get("late_penalty_per_day", 0.0)
    if not isinstance(per_day, (int, float)) or not 0 <= per_day <= 1:
        raise UsageError(f"{path}: {where} late_penalty_per_day must be a fraction in [0, 1] "
                         f"(0.1 is 10% off per day); got {per_day!r}.")
    max_days = item.get("max_late_days", 0)
    if not isinstance(max_days, int) or max_days < 0:
        raise UsageError(f"{path}: {where} max_late_days must be a whole number >= 0; got {max_days!r}.")
    count = item.get("count", "best")
    if count not in ("best", "last"):
        raise UsageError(f"{path}: {where} count must be \"best\" or \"last\"; got {count!r}.")
    extensions = item.get("extensions", {})
    if not isinstance(extensions, dict):
        raise UsageError(f"{path}: {where} extensions must be a table of student id = date-time.")
    return AssignmentPolicy(
        name=name, spec=spec, title=str(item.get("title", name)), opens=opens, deadline=deadline,
        late_penalty_per_day=float(per_day), max_late_days=max_days, count=count,
        public_only=bool(item.get("public_only", False)),
        extensions=tuple((str(k), _when(path, f"{where} extensions.{k}", v, zone))
                         for k, v in extensions.items()))
