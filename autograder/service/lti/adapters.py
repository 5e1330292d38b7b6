"""PyLTI1p3 on FastAPI: the request, cookie, session, redirect and launch-data classes it expects.

PyLTI1p3 ships adapters for Django and Flask only; each class below is the
FastAPI/Starlette counterpart of one of them (``pylti1p3/contrib/flask``), so the
protocol itself (state, nonce, signature, issuer, audience, expiry, deployment,
message checks, service tokens) stays PyLTI1p3's.
"""

from __future__ import annotations

import datetime as dt
import json
from typing import Any, Mapping

import requests
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from pylti1p3.cookie import CookieService
from pylti1p3.launch_data_storage.base import LaunchDataStorage
from pylti1p3.message_launch import MessageLaunch
from pylti1p3.oidc_login import OIDCLogin
from pylti1p3.redirect import Redirect
from pylti1p3.request import Request
from pylti1p3.session import SessionService
from sqlalchemy import delete
from sqlalchemy.orm import Session, sessionmaker

from autograder.service.lti.tables import LtiState
from autograder.service.models import utcnow

#: seconds an LMS call may take before it counts as failed (requests has no default timeout)
HTTP_TIMEOUT = 15.0


class LtiRequest(Request):
    """The parameters and cookies of one Starlette request, read before PyLTI1p3 sees them.

    Exists because PyLTI1p3 reads parameters synchronously and Starlette's form is async.
    """

    def __init__(self, params: Mapping[str, str], cookies: Mapping[str, str], secure: bool) -> None:
        self._params, self._cookies, self._secure = dict(params), dict(cookies), secure

    @property
    def session(self) -> dict[str, Any]:
        return {}  # launch data lives in the database (DatabaseStorage), never here

    def get_param(self, key: str) -> Any:
        return self._params.get(key)

    def get_cookie(self, key: str) -> str | None:
        return self._cookies.get(key)

    def is_secure(self) -> bool:
        return self._secure


class LtiCookies(CookieService):
    """Collects the state cookies PyLTI1p3 sets and writes them onto the FastAPI response.

    Over HTTPS they are ``SameSite=None; Secure``: the launch is a cross-site POST from
    the LMS, which would not carry a ``Lax`` cookie.
    """

    def __init__(self, request: LtiRequest) -> None:
        self._request = request
        self._pending: dict[str, tuple[str, int | None]] = {}

    def _key(self, name: str) -> str:
        return f"{self._cookie_prefix}-{name}"

    def get_cookie(self, name: str) -> str | None:
        return self._request.get_cookie(self._key(name))

    def set_cookie(self, name: str, value: str | int, exp: int | None = 3600) -> None:
        self._pending[self._key(name)] = (str(value), exp)

    def apply(self, response: Response) -> Response:
        secure = self._request.is_secure()
        for key, (value, exp) in self._pending.items():
            response.set_cookie(key, value, max_age=exp, path="/", httponly=True, secure=secure,
                                samesite="none" if secure else "lax")
        return response


class DatabaseStorage(LaunchDataStorage[Any]):
    """State, nonces and launch data in the ``lti_state`` table, shared by every service process.

    Exists because PyLTI1p3's own storages are a framework session or a Django cache,
    neither of which this service has. Keys are bound to the browser by PyLTI1p3's
    ``lti1p3-session-id`` cookie.
    """

    _session_cookie_name = "session-id"

    def __init__(self, factory: sessionmaker[Session], lifetime: int = 3600) -> None:
        super().__init__()
        self._factory, self._lifetime = factory, lifetime

    def can_set_keys_expiration(self) -> bool:
        return True

    def get_value(self, key: str) -> Any:
        with self._factory() as session:
            row = session.get(LtiState, self._prepare_key(key))
            if row is None or row.expires_at <= utcnow():
                return None
            return json.loads(row.value)

    def set_value(self, key: str, value: Any, exp: int | None = None) -> None:
        expires = utcnow() + dt.timedelta(seconds=exp or self._lifetime)
        with self._factory.begin() as session:
            session.execute(delete(LtiState).where(LtiState.expires_at <= utcnow()))
            session.merge(LtiState(key=self._prepare_key(key), value=json.dumps(value),
                                   expires_at=expires))

    def check_value(self, key: str) -> bool:
        return self.get_value(key) is not None

    def take(self, key: str) -> bool:
        """Delete ``key``; whether it was there (one caller wins: the row is deleted once)."""
        with self._factory.begin() as session:
            done = session.execute(delete(LtiState).where(LtiState.key == self._prepare_key(key),
                                                          LtiState.expires_at > utcnow()))
            return bool(done.rowcount)


class OneTimeNonces(SessionService):
    """PyLTI1p3's session service whose nonces work once: a replayed launch is refused.

    PyLTI1p3 only checks that the nonce was issued; deleting it on use stops a replay.
    """

    data_storage: DatabaseStorage

    def __init__(self, request: LtiRequest, storage: DatabaseStorage) -> None:
        super().__init__(request)
        self.data_storage = storage

    def check_nonce(self, nonce: str) -> bool:
        return self.data_storage.take(self._get_key("nonce", nonce))


class LtiRedirect(Redirect[Response]):
    """The redirect from the OIDC login to the platform's authorisation endpoint, with cookies."""

    def __init__(self, location: str, cookies: LtiCookies) -> None:
        self._location, self._cookies = location, cookies

    def do_redirect(self) -> Response:
        return self._cookies.apply(RedirectResponse(self._location, status_code=302))

    def do_js_redirect(self) -> Response:
        return self.do_redirect()  # the pages allow no inline script; a plain redirect works

    def set_redirect_url(self, location: str) -> None:
        self._location = location

    def get_redirect_url(self) -> str:
        return self._location


class TimedSession(requests.Session):
    """A requests session whose calls time out (PyLTI1p3 passes none: an LMS that hangs
    would hold the sender forever)."""

    def request(self, *args: Any, **kwargs: Any) -> requests.Response:  # type: ignore[override]
        kwargs.setdefault("timeout", HTTP_TIMEOUT)
        return super().request(*args, **kwargs)


class FastApiOIDCLogin(OIDCLogin):
    def __init__(self, request: LtiRequest, tool_conf: Any, storage: DatabaseStorage) -> None:
        cookies = LtiCookies(request)
        super().__init__(request, tool_conf, OneTimeNonces(request, storage), cookies, storage)

    def get_redirect(self, url: str) -> LtiRedirect:
        return LtiRedirect(url, self._cookie_service)

    def get_response(self, html: str) -> Response:
        return HTMLResponse(html)

    def _get_request_param(self, key: str) -> Any:
        return self._request.get_param(key)


class FastApiMessageLaunch(MessageLaunch):
    def __init__(self, request: LtiRequest, tool_conf: Any, storage: DatabaseStorage) -> None:
        super().__init__(request, tool_conf, OneTimeNonces(request, storage), LtiCookies(request),
                         storage, TimedSession())

    def _get_request_param(self, key: str) -> Any:
        return self._request.get_param(key)
