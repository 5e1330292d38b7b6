"""The tool's signing key: made once, at the service's first start, kept in the database.

PyLTI1p3 signs with a PEM key and the platforms verify with the JWKS served at
``/lti/jwks``; the key id is the key's JWK thumbprint (what PyLTI1p3 puts in the
``kid`` header), so the pair is found again from the PEM alone.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from jwcrypto.jwk import JWK
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from autograder.service.lti.tables import LtiKey


@dataclass(frozen=True)
class ToolKey:
    kid: str
    private_pem: str
    public_pem: str

    def jwks(self) -> dict[str, Any]:
        jwk = json.loads(JWK.from_pem(self.public_pem.encode()).export_public())
        return {"keys": [{**jwk, "kid": self.kid, "alg": "RS256", "use": "sig"}]}


def _new_row() -> LtiKey:
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption()).decode()
    return LtiKey(id=1, kid=JWK.from_pem(pem.encode()).thumbprint(), private_pem=pem)


def tool_key(factory: sessionmaker[Session]) -> ToolKey:
    """The tool's key pair, made and stored the first time (a second process finds the first's)."""
    with factory() as session:
        row = session.get(LtiKey, 1)
    if row is None:
        try:
            with factory.begin() as session:
                session.add(_new_row())
        except IntegrityError:  # another process stored its key first: use that one
            pass
        with factory() as session:
            row = session.get(LtiKey, 1)
    assert row is not None
    private = serialization.load_pem_private_key(row.private_pem.encode(), password=None)
    public = private.public_key().public_bytes(serialization.Encoding.PEM,
                                               serialization.PublicFormat.SubjectPublicKeyInfo)
    return ToolKey(row.kid, row.private_pem, public.decode())
