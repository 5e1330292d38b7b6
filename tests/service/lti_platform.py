"""A small LTI 1.3 platform (an LMS stand-in) for the LTI tests and for trying the tool locally.

The protocol is lti1p3platform's (an implementation independent of the tool's
PyLTI1p3): its registration signs the launches and the deep-linking requests,
checks the tool's deep-linking responses and service-token requests against the
tool's JWKS, and issues and checks the access tokens. lti1p3platform has no
server, no course and no gradebook, so this module adds the thin FastAPI app
around its classes: a course with members (NRPS), line items that keep the
scores posted to them (AGS), links made by deep linking, and launches that can
be forged (for the refusal tests) or replayed.

Run it beside ``autograder serve`` (see docs/lti.md)::

    PYTHONPATH=tests/service python -m lti_platform --tool http://127.0.0.1:8000 --port 9001
"""

from __future__ import annotations

import argparse
import base64
import itertools
import json
import secrets
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import jwt
import uvicorn
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import HTMLResponse, JSONResponse, Response
from lti1p3platform.framework.fastapi.oidc_login import FastAPIOIDCLogin
from lti1p3platform.framework.templates import template
from lti1p3platform.ltiplatform import LTI1P3PlatformConfAbstract
from lti1p3platform.message_launch import LTIAdvantageMessageLaunchAbstract
from lti1p3platform.registration import Registration

ROLE = "http://purl.imsglobal.org/vocab/lis/v2/membership#"
SCORE = "https://purl.imsglobal.org/spec/lti-ags/scope/score"
MEMBERS = "https://purl.imsglobal.org/spec/lti-nrps/scope/contextmembership.readonly"
FORGERIES = ("bad-signature", "wrong-audience", "expired", "wrong-deployment")


def _pem_pair() -> tuple[str, str]:
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    private = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                serialization.NoEncryption()).decode()
    public = key.public_key().public_bytes(serialization.Encoding.PEM,
                                           serialization.PublicFormat.SubjectPublicKeyInfo).decode()
    return private, public


class PlatformConfig(LTI1P3PlatformConfAbstract):
    """lti1p3platform's registration of the tool, as an LMS admin would enter it."""

    def init_platform_config(self, **kwargs: Any) -> None:
        private, public = kwargs["keys"]
        tool = kwargs["tool"].rstrip("/")
        self._registration = (
            Registration().set_iss(kwargs["issuer"]).set_client_id(kwargs["client_id"])
            .set_deployment_id(kwargs["deployment_id"]).set_oidc_login_url(f"{tool}/lti/login")
            .set_launch_url(f"{tool}/lti/launch").set_deeplink_launch_url(f"{tool}/lti/launch")
            .set_platform_private_key(private).set_platform_public_key(public)
            .set_tool_key_set_url(f"{tool}/lti/jwks"))

    def get_registration_by_params(self, **kwargs: Any) -> Registration:
        assert self._registration is not None
        return self._registration


class Login(FastAPIOIDCLogin):
    def set_lti_message_hint(self, **kwargs: Any) -> None:
        self._lti_message_hint = kwargs["hint"]


class Launch(LTIAdvantageMessageLaunchAbstract):
    """lti1p3platform's launch; ``forge`` spoils the id_token the way an attacker would."""

    forge: str = ""

    def get_preflight_response(self) -> dict[str, Any]:
        return dict(self._request.query_params)

    def render_launch_form(self, launch_data: dict[str, Any], **kwargs: Any) -> Response:
        return HTMLResponse(template.render(launch_data))

    def generate_launch_request(self) -> Any:
        data = super().generate_launch_request()
        if not self.forge:
            return data
        token = data["id_token"]
        if self.forge == "bad-signature":  # the claims changed after signing
            head, body, sig = token.split(".")
            claims = json.loads(base64.urlsafe_b64decode(body + "=" * (-len(body) % 4)))
            claims["sub"] = "prof"
            body = base64.urlsafe_b64encode(json.dumps(claims).encode()).rstrip(b"=").decode()
            return {**data, "id_token": f"{head}.{body}.{sig}"}
        claims = jwt.decode(token, options={"verify_signature": False})
        if self.forge == "wrong-audience":
            claims["aud"] = claims["azp"] = "another-tool"
        elif self.forge == "expired":
            claims["iat"], claims["exp"] = int(time.time()) - 600, int(time.time()) - 300
        elif self.forge == "wrong-deployment":
            claims["https://purl.imsglobal.org/spec/lti/claim/deployment_id"] = "deployment-unknown"
        registration = self._platform_config.get_registration()
        signed = jwt.encode(claims, registration.get_platform_private_key(), algorithm="RS256",
                            headers={"kid": registration.get_kid()})
        return {**data, "id_token": signed}


@dataclass
class Course:
    """The LMS course: people, links (from deep linking), line items and their scores."""

    people: dict[str, tuple[str, str, str]] = field(default_factory=dict)  # sub: name, email, role
    links: dict[str, dict[str, Any]] = field(default_factory=dict)
    lineitems: dict[str, dict[str, Any]] = field(default_factory=dict)
    scores: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    pending: dict[str, dict[str, Any]] = field(default_factory=dict)
    last_form: dict[str, str] = field(default_factory=dict)
    deep_linked: list[dict[str, Any]] = field(default_factory=list)


class Platform:
    """The FastAPI app of the platform at ``url`` for the tool at ``tool``, and its server."""

    def __init__(self, *, tool: str, port: int, issuer: str | None = None,
                 client_id: str = "numgrade-client", deployment_id: str = "deployment-1") -> None:
        self.port, self.url = port, f"http://127.0.0.1:{port}"
        self.issuer, self.client_id, self.deployment_id = issuer or self.url, client_id, deployment_id
        self.keys = _pem_pair()
        self.tool = tool.rstrip("/")
        self.course = Course()
        self._ids = itertools.count(1)
        self.app = self._make_app()
        self._server: uvicorn.Server | None = None
        self._thread: threading.Thread | None = None

    def config(self) -> PlatformConfig:
        return PlatformConfig(keys=self.keys, tool=self.tool, issuer=self.issuer,
                              client_id=self.client_id, deployment_id=self.deployment_id)

    def course_toml(self) -> str:
        """The ``[[lti.platforms]]`` table the tool's course file needs for this platform."""
        return (f'[[lti.platforms]]\nissuer = "{self.issuer}"\nclient_id = "{self.client_id}"\n'
                f'deployment_ids = ["{self.deployment_id}"]\n'
                f'auth_login_url = "{self.url}/authorize"\nauth_token_url = "{self.url}/token"\n'
                f'key_set_url = "{self.url}/jwks"\n')

    def add_person(self, sub: str, name: str, email: str, role: str) -> None:
        self.course.people[sub] = (name, email, role)

    def add_link(self, custom: dict[str, str], *, title: str = "link") -> str:
        """A resource link made by hand (as an instructor typing a custom parameter)."""
        item = str(next(self._ids))
        self.course.lineitems[item] = {"label": title, "scoreMaximum": 100}
        link = f"link-{item}"
        self.course.links[link] = {"custom": custom, "lineitem": item, "title": title}
        return link

    # -- the server -------------------------------------------------------------------

    def start(self) -> "Platform":
        self._server = uvicorn.Server(uvicorn.Config(self.app, host="127.0.0.1", port=self.port,
                                                     log_level="warning", access_log=False))
        self._thread = threading.Thread(target=self._server.run, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 30
        while not self._server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise AssertionError("the LTI test platform did not start")
            time.sleep(0.05)
        return self

    def stop(self) -> None:
        if self._server is not None and self._thread is not None:
            self._server.should_exit = True
            self._thread.join(30)
            self._server = self._thread = None

    # -- routes -----------------------------------------------------------------------

    def _make_app(self) -> FastAPI:
        app = FastAPI(docs_url=None, redoc_url=None, openapi_url=None)
        app.get("/jwks")(lambda: JSONResponse(self._jwks()))
        app.get("/launch/{sub}")(self._start)
        app.get("/authorize")(self._authorize)
        app.get("/replay/{sub}")(self._replay)
        app.post("/token")(self._token)
        app.post("/lineitems/{item}/scores")(self._score)
        app.get("/lineitems/{item}")(self._lineitem)
        app.get("/memberships")(self._members)
        app.get("/gradebook")(self._gradebook)
        app.post("/deep-link-return")(self._deep_link_return)
        return app

    def _jwks(self) -> dict[str, Any]:
        config = self.config()
        config.get_registration()
        return dict(config.get_jwks())

    def _start(self, sub: str, link: str = "", deep_link: bool = False, forge: str = "") -> Response:
        """The LMS page's link: start the OIDC third-party login at the tool."""
        if sub not in self.course.people or (link and link not in self.course.links):
            raise HTTPException(404, "no such person or link in the test course")
        hint = secrets.token_urlsafe(8)
        self.course.pending[hint] = {"sub": sub, "link": link, "deep_link": deep_link, "forge": forge}
        login = Login(None, self.config())
        login.set_lti_message_hint(hint=hint)
        return login.initiate_login(sub)

    def _authorize(self, request: Request) -> Response:
        """The platform's OIDC authorisation endpoint: answer with the signed launch form."""
        pending = self.course.pending.pop(request.query_params.get("lti_message_hint", ""), None)
        if pending is None or pending["sub"] != request.query_params.get("login_hint"):
            raise HTTPException(400, "unknown launch")
        launch = Launch(request, self.config())
        launch.forge = pending["forge"]
        name, email, role = self.course.people[pending["sub"]]
        launch.set_user_data(pending["sub"], [ROLE + role], name, email)
        launch.set_launch_context_claim("course-1", context_title="Numerical methods")
        launch.set_nrps(f"{self.url}/memberships")
        if pending["deep_link"]:
            launch.set_dl(f"{self.url}/deep-link-return", title="numgrade",
                          accept_types={"ltiResourceLink"})
        else:
            link = self.course.links[pending["link"]]
            launch.set_resource_link_claim(pending["link"], title=link["title"])
            launch.set_custom_parameters_claim(link["custom"])
            launch.set_ags(f"{self.url}/lineitems", f"{self.url}/lineitems/{link['lineitem']}")
        response = launch.lti_launch()
        self.course.last_form[pending["sub"]] = response.body.decode()
        return response

    def _replay(self, sub: str) -> Response:
        """The last launch form of ``sub`` again: the same id_token and state, sent twice."""
        return HTMLResponse(self.course.last_form[sub])

    async def _token(self, request: Request) -> Response:
        form = dict(await request.form())
        try:
            return JSONResponse(dict(self.config().get_access_token(form)))
        except Exception as exc:  # the tool's assertion was refused: the answer says why
            return JSONResponse({"error": "invalid_client", "detail": str(exc)}, status_code=400)

    def _check(self, request: Request, scope: str) -> None:
        token = request.headers.get("authorization", "")[7:]
        config = self.config()
        config.get_registration()
        try:
            ok = config.validate_token(token, allowed_scopes=[scope])
        except Exception:
            ok = False
        if not ok:
            raise HTTPException(401, "invalid access token")

    async def _score(self, item: str, request: Request) -> Response:
        self._check(request, SCORE)
        if item not in self.course.lineitems:
            raise HTTPException(404, "no such line item")
        self.course.scores.setdefault(item, []).append(await request.json())
        return JSONResponse({})

    def _gradebook(self) -> Response:
        """The LMS gradebook a person reads: each line item with the last score per user."""
        import html

        rows = []
        for item, line in self.course.lineitems.items():
            last = {s.get("userId"): s for s in self.course.scores.get(item, [])}
            for user, score in sorted(last.items()):
                rows.append(f"<tr><td>{html.escape(str(line.get('label', item)))}</td>"
                            f"<td>{html.escape(str(user))}</td>"
                            f"<td class='score'>{score.get('scoreGiven')} / "
                            f"{score.get('scoreMaximum')}</td></tr>")
        return HTMLResponse("<!doctype html><title>Gradebook</title><h1>Gradebook</h1>"
                            "<table><tr><th>item</th><th>user</th><th>score</th></tr>"
                            + "".join(rows) + "</table>")

    def _lineitem(self, item: str, request: Request) -> Response:
        return JSONResponse({"id": f"{self.url}/lineitems/{item}", **self.course.lineitems[item]})

    def _members(self, request: Request) -> Response:
        self._check(request, MEMBERS)
        return JSONResponse({"id": f"{self.url}/memberships", "context": {"id": "course-1"},
                             "members": [{"user_id": sub, "name": n, "email": e, "status": "Active",
                                          "roles": [ROLE + r]}
                                         for sub, (n, e, r) in self.course.people.items()]})

    async def _deep_link_return(self, request: Request) -> Response:
        form = dict(await request.form())
        config = self.config()
        config.get_registration()
        items = config.validate_deeplinking_resp({"JWT": form["JWT"]})
        for content in items:
            item = str(next(self._ids))
            line = content.get("lineItem", {})
            self.course.lineitems[item] = {"label": line.get("label", ""),
                                           "scoreMaximum": line.get("scoreMaximum", 100)}
            self.course.links[f"link-{item}"] = {"custom": content.get("custom", {}),
                                                 "lineitem": item, "title": content.get("title", "")}
        self.course.deep_linked.extend(items)
        return HTMLResponse(f"<p id='added'>Added {len(items)} item(s): "
                            f"{', '.join('link-' + str(k) for k in self.course.links)}</p>")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tool", default="http://127.0.0.1:8000", help="the numgrade service's URL")
    parser.add_argument("--port", type=int, default=9001)
    args = parser.parse_args()
    platform = Platform(tool=args.tool, port=args.port)
    platform.add_person("prof-1", "Prof Ada", "ada@example.edu", "Instructor")
    platform.add_person("student-1", "Alice", "alice@example.edu", "Learner")
    print("Add this to the course file and restart `autograder serve`:\n")
    print(platform.course_toml())
    print(f"Then open {platform.url}/launch/prof-1?deep_link=true to add an assignment, and "
          f"{platform.url}/launch/student-1?link=link-1 to launch it as a student.")
    platform.start()
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        platform.stop()


if __name__ == "__main__":
    main()
