"""``[[lti.platforms]]`` in the course file: read with every key, a bad one named with the fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from autograder.errors import UsageError
from autograder.service.course import load_course
from autograder.service.lti.accounts import service_role

BASE = """
[[assignment]]
name = "hull"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""
PLATFORM = """
[[lti.platforms]]
issuer = "https://canvas.instructure.com"
client_id = "{client}"
deployment_ids = {deployments}
auth_login_url = "https://sso.canvaslms.com/api/lti/authorize_redirect"
auth_token_url = "https://sso.canvaslms.com/login/oauth2/token"
key_set_url = "https://sso.canvaslms.com/api/lti/security/jwks"
"""


def course(tmp_path: Path, *platforms: str) -> Path:
    path = tmp_path / "course.toml"
    path.write_text(BASE + "".join(platforms))
    return path


def test_two_registrations_of_one_issuer_are_read(tmp_path: Path) -> None:
    loaded = load_course(course(tmp_path, PLATFORM.format(client="1", deployments='["a"]'),
                                PLATFORM.format(client="2", deployments='["b", "c"]')))
    assert [(p.client_id, p.deployment_ids) for p in loaded.lti_platforms] == [
        ("1", ("a",)), ("2", ("b", "c"))]


@pytest.mark.parametrize("text, words", [
    (PLATFORM.format(client="1", deployments='"a"'), "deployment_ids must be a list"),
    (PLATFORM.format(client="1", deployments="[]"), "deployment_ids must be a list"),
    (PLATFORM.format(client="1", deployments='["a"]').replace("key_set_url", "keyset_url"),
     "needs exactly the keys"),
    (PLATFORM.format(client="", deployments='["a"]'), "client_id must be a non-empty string"),
    (PLATFORM.format(client="1", deployments='["a"]') * 2, "same issuer and client_id"),
])
def test_a_bad_platform_is_named(tmp_path: Path, text: str, words: str) -> None:
    with pytest.raises(UsageError, match="lti.platforms|same issuer") as info:
        load_course(course(tmp_path, text))
    assert words in str(info.value)


@pytest.mark.parametrize("roles, role", [
    (["http://purl.imsglobal.org/vocab/lis/v2/membership#Learner"], "student"),
    (["http://purl.imsglobal.org/vocab/lis/v2/membership#Instructor"], "instructor"),
    (["http://purl.imsglobal.org/vocab/lis/v2/membership#Instructor",
      "http://purl.imsglobal.org/vocab/lis/v2/membership/Instructor#TeachingAssistant"], "ta"),
    (["http://purl.imsglobal.org/vocab/lis/v2/institution/person#Student"], "student"),
    ([], "student"),
])
def test_lti_roles_map_to_the_services_roles(roles: list[str], role: str) -> None:
    assert service_role(roles) == role
