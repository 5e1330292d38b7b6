"""The tool's registrations for PyLTI1p3: every ``[[lti.platforms]]`` of the course file."""

from __future__ import annotations

from pylti1p3.tool_config import ToolConfDict

from autograder.service.course import Course
from autograder.service.lti.keys import ToolKey


def tool_conf(course: Course, key: ToolKey) -> ToolConfDict:
    """One issuer may hold several client ids (several LMS courses or registrations)."""
    by_issuer: dict[str, list[dict[str, object]]] = {}
    for p in course.lti_platforms:
        by_issuer.setdefault(p.issuer, []).append({
            "default": not by_issuer.get(p.issuer), "client_id": p.client_id,
            "auth_login_url": p.auth_login_url, "auth_token_url": p.auth_token_url,
            "key_set_url": p.key_set_url, "deployment_ids": list(p.deployment_ids)})
    conf = ToolConfDict(by_issuer)
    for p in course.lti_platforms:
        conf.set_private_key(p.issuer, key.private_pem, client_id=p.client_id)
        conf.set_public_key(p.issuer, key.public_pem, client_id=p.client_id)
    return conf
