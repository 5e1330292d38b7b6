"""The LTI 1.3 routes: JWKS, OIDC login initiation, launch, and the deep-linking chooser.

A resource-link launch signs the LMS user in (a browser session, as the token
sign-in makes) and opens the assignment the link's custom parameter
``assignment`` names; a student's launch also records the line item their
score goes to (:mod:`~autograder.service.lti.outbox`). An instructor's launch
adds the LMS course's members to the roster (NRPS) when the platform offers it.
A deep-linking request from an instructor lists the course's assignments;
choosing one returns a signed ``LtiDeepLinkingResponse`` with a resource link
and a line item. Every check of a launch is PyLTI1p3's (plus one-time nonces);
a refused launch gets a page saying what was wrong, never a traceback.
"""

from __future__ import annotations

import logging
import secrets
from typing import Any, Mapping
from urllib.parse import urlsplit

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import JSONResponse, RedirectResponse, Response
from pylti1p3.deep_link import DeepLink
from pylti1p3.deep_link_resource import DeepLinkResource
from pylti1p3.exception import LtiException
from pylti1p3.lineitem import LineItem
from pylti1p3.oidc_login import OIDCException
from sqlalchemy import select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from autograder.service import auth
from autograder.service.lti.accounts import account_user, import_members, person_from_launch
from autograder.service.lti.adapters import (DatabaseStorage, FastApiMessageLaunch, FastApiOIDCLogin,
                                             LtiRequest)
from autograder.service.lti.config import tool_conf
from autograder.service.lti.keys import tool_key
from autograder.service.lti.tables import LtiLink
from autograder.service.web import PAGE_CSP, SESSION_COOKIE, Instructor, Service, ServiceState, check_csrf

log = logging.getLogger("autograder.service.lti")
router = APIRouter()

LAUNCH_PATH = "/lti/launch"
#: what a refused launch's page says, by what PyLTI1p3 found (its messages are terse)
_REASONS = (
    ("Invalid Nonce", 400, "This launch was already used, or its sign-in expired (the nonce is "
                           "not one this tool issued and has not used yet)."),
    ("State not found", 400, "The launch does not belong to a sign-in this browser started (state "
                             "cookie missing or different); allow cookies for this site."),
    ("Signature has expired", 400, "The launch has expired (its exp claim is in the past)."),
    ("Signature verification failed", 403, "The launch's signature does not match the "
                                           "platform's published keys."),
    ("[client_id=", 403, "The launch is for a client id (audience, aud) this tool has no "
                         "registration for."),
    ("not found in settings", 403, "The launch comes from an issuer this tool has no "
                                   "registration for."),
    ("Client id not registered", 403, "The launch is for a client id (audience, aud) this tool "
                                      "has no registration for."),
    ("Registration not found", 403, "The launch comes from an issuer this tool has no "
                                    "registration for."),
    ("Unable to find deployment", 403, "The launch's deployment id is not one of the "
                                       "registration's deployment_ids."),
    ("Unable to find public key", 403, "The launch is signed with a key the platform does not "
                                       "publish."),
)
_ADVICE = (" Open the assignment again from your course in the LMS; if this keeps happening, send "
           "this message to your instructor (the LTI setup is described in docs/lti.md).")


def _refused(svc: Service, exc: Exception) -> Response:
    text = str(exc)
    for needle, status, reason in _REASONS:
        if needle.lower() in text.lower():
            break
    else:
        status, reason = 400, f"The LTI launch is not valid: {text[:300]}."
    return svc.page("error.html.j2", None, status=status, message=reason + _ADVICE)


async def _lti_request(request: Request) -> LtiRequest:
    params: Mapping[str, Any] = request.query_params
    if request.method == "POST":
        params = {**request.query_params, **await request.form(max_files=0, max_fields=40)}
    secure = request.url.scheme == "https"
    return LtiRequest({k: str(v) for k, v in params.items()}, request.cookies, secure)


@router.get("/lti/jwks")
def jwks(svc: ServiceState) -> Response:
    return JSONResponse(tool_key(svc.factory).jwks())


@router.api_route("/lti/login", methods=["GET", "POST"])
async def login(request: Request, svc: ServiceState) -> Response:
    """OIDC third-party login initiation: redirect to the platform with a state and a nonce."""
    lti = await _lti_request(request)
    target = lti.get_param("target_link_uri") or ""
    if urlsplit(target).path != LAUNCH_PATH:
        return svc.page("error.html.j2", None, status=400, message=(
            f"The LMS asked to launch {target[:200]!r}; this tool launches only at its "
            f"{LAUNCH_PATH} URL. Set the tool's target link URI (redirect URI) to it."))
    return await run_in_threadpool(_login, svc, lti, target)


def _login(svc: Service, lti: LtiRequest, target: str) -> Response:
    conf = tool_conf(svc.course, tool_key(svc.factory))
    try:
        return FastApiOIDCLogin(lti, conf, DatabaseStorage(svc.factory)).redirect(target)
    except (LtiException, OIDCException) as exc:
        return _refused(svc, exc)


@router.post(LAUNCH_PATH)
async def launch(request: Request, svc: ServiceState) -> Response:
    lti = await _lti_request(request)
    return await run_in_threadpool(_launch, svc, lti)


def _launch(svc: Service, lti: LtiRequest) -> Response:
    conf = tool_conf(svc.course, tool_key(svc.factory))
    message = FastApiMessageLaunch(lti, conf, DatabaseStorage(svc.factory))
    try:
        claims = message.get_launch_data()
    except (LtiException, OIDCException) as exc:
        return _refused(svc, exc)
    except Exception as exc:  # PyLTI1p3 raises bare exceptions for some malformed tokens
        log.warning("LTI launch refused: %r", exc)
        return _refused(svc, exc)
    person = person_from_launch(claims)
    if message.is_deep_link_launch():
        return _deep_link_chooser(svc, claims, person)
    custom = claims.get("https://purl.imsglobal.org/spec/lti/claim/custom") or {}
    policy = svc.course.assignment(str(custom.get("assignment", "")))
    if policy is None:
        return svc.page("error.html.j2", None, status=400, message=(
            f"This LMS link names the assignment {custom.get('assignment')!r}, which this course "
            "does not have. The instructor sets it as the custom parameter assignment=NAME, or "
            "adds the link again through the tool's assignment chooser (deep linking)."))
    with svc.factory.begin() as session:
        user = account_user(session, claims["iss"], person)
        lineitem = (claims.get("https://purl.imsglobal.org/spec/lti-ags/claim/endpoint") or {}
                    ).get("lineitem")
        if person.role == "student" and lineitem:
            _link(session, user.id, policy.name, claims, str(lineitem))
        cookie = auth.open_session(session, user)
    note = _roster(svc, message, claims["iss"]) if person.role == "instructor" else ""
    target = f"/assignments/{policy.name}" if person.role == "student" else "/instructor"
    return _signed_in(svc, target + (f"?lti={note}" if note else ""), cookie)


def _signed_in(svc: Service, target: str, cookie: str) -> Response:
    """Go to ``target`` with the browser session the launch opened (as the token sign-in sets it)."""
    response = RedirectResponse(target, status_code=303)
    response.set_cookie(SESSION_COOKIE, cookie, httponly=True, samesite="lax", path="/",
                        max_age=int(svc.course.session_lifetime.total_seconds()))
    return response


def _link(session: Session, user_id: str, assignment: str, claims: Mapping[str, Any], lineitem: str
          ) -> None:
    known = session.scalars(select(LtiLink).where(
        LtiLink.user_id == user_id, LtiLink.assignment == assignment,
        LtiLink.lineitem == lineitem)).first()
    if known is None:
        aud = claims.get("aud")
        session.add(LtiLink(user_id=user_id, assignment=assignment, issuer=claims["iss"],
                            client_id=str(aud[0] if isinstance(aud, list) else aud),
                            sub=str(claims["sub"]), lineitem=lineitem))


def _roster(svc: Service, message: FastApiMessageLaunch, issuer: str) -> str:
    """Add the LMS course's members (NRPS); a failure is logged, never stops the sign-in."""
    if not message.has_nrps():
        return ""
    try:
        members = message.get_nrps().get_members()
    except (LtiException, OSError, ValueError) as exc:
        log.warning("the LMS roster (NRPS) could not be read: %s", exc)
        return "roster-failed"
    with svc.factory.begin() as session:
        added, _ = import_members(session, issuer, members)
    return f"roster-{added}-added"


# -- deep linking -----------------------------------------------------------------------

def _deep_link_chooser(svc: Service, claims: Mapping[str, Any], person: Any) -> Response:
    if person.role != "instructor":
        return svc.page("error.html.j2", None, status=403, message=(
            "Only an instructor of the LMS course may add this tool's assignments to it."))
    ticket = secrets.token_urlsafe(24)
    storage = DatabaseStorage(svc.factory)
    storage.set_value(f"deep-link-{ticket}", dict(claims), exp=3600)
    with svc.factory.begin() as session:
        user = account_user(session, claims["iss"], person)
        cookie = auth.open_session(session, user)
    return _signed_in(svc, f"/lti/deep-link/{ticket}", cookie)


def _deep_link_claims(svc: Service, ticket: str) -> dict[str, Any]:
    claims = DatabaseStorage(svc.factory).get_value(f"deep-link-{ticket}")
    if not claims:
        raise HTTPException(404, "This assignment chooser has expired; open it again from the LMS.")
    return claims


@router.get("/lti/deep-link/{ticket}")
def deep_link_page(ticket: str, who: Instructor, svc: ServiceState) -> Response:
    _deep_link_claims(svc, ticket)
    return svc.page("lti_deep_link.html.j2", who, ticket=ticket)


@router.post("/lti/deep-link/{ticket}")
async def deep_link_choose(ticket: str, request: Request, who: Instructor, svc: ServiceState
                           ) -> Response:
    form = await request.form(max_files=0, max_fields=10)
    check_csrf(who, form, request)
    policy = svc.policy(str(form.get("assignment", "")))
    claims = await run_in_threadpool(_deep_link_claims, svc, ticket)
    conf = tool_conf(svc.course, await run_in_threadpool(tool_key, svc.factory))
    registration = conf.find_registration_by_params(claims["iss"], _aud(claims))
    settings = claims["https://purl.imsglobal.org/spec/lti-dl/claim/deep_linking_settings"]
    deployment = claims["https://purl.imsglobal.org/spec/lti/claim/deployment_id"]
    launch_url = str(request.base_url).rstrip("/") + LAUNCH_PATH
    resource = (DeepLinkResource().set_url(launch_url).set_title(policy.title)
                .set_custom_params({"assignment": policy.name})
                .set_lineitem(LineItem().set_score_maximum(100).set_label(policy.title)
                              .set_resource_id(policy.name)))
    token = DeepLink(registration, deployment, settings).get_response_jwt([resource])
    back = settings["deep_link_return_url"]
    origin = "{0.scheme}://{0.netloc}".format(urlsplit(back))
    page = svc.page("lti_deep_link_return.html.j2", who, back=back, jwt=token, title=policy.title)
    # the one form of the site that goes elsewhere: back to the LMS that asked
    page.headers["Content-Security-Policy"] = PAGE_CSP.replace("form-action 'self'",
                                                               f"form-action {origin}")
    return page


def _aud(claims: Mapping[str, Any]) -> str:
    aud = claims.get("aud")
    return str(aud[0] if isinstance(aud, list) else aud)

