"""Bearer-token authentication, checked before anything else looks at a request.

With ``DRT_API_TOKEN`` set, every path but ``/healthz`` and the job monitor's static shell (``api.web.is_public``:
the page holds no data; it asks for the token and sends it with every API call) needs ``Authorization: Bearer <token>``. ``TokenFirst`` is
ASGI middleware, so it answers 401 before the body of a request is read (FastAPI resolves route dependencies only
after parsing the body, so a dependency alone would let an unauthenticated client have its multipart parsed). The
comparison is constant-time. Clients are told apart by their token, else by their address (the queue limits).
"""
from __future__ import annotations

import hashlib
import hmac
import json

from ..errors import UNAUTHORIZED
from .web import is_public

PUBLIC_PATHS = frozenset({"/healthz"})
CHALLENGE = {"WWW-Authenticate": "Bearer"}


def bearer_ok(expected: str | None, authorization: str | None) -> bool:
    """True if no token is required, or ``authorization`` is ``Bearer <expected>`` (constant-time compare)."""
    if expected is None:
        return True
    scheme, _, given = (authorization or "").partition(" ")
    # compare_digest's time does not depend on where the bytes differ (only on their length); a header's bytes
    # arrive as latin-1 text, so encoding it back gives exactly what the client sent.
    return scheme.lower() == "bearer" and hmac.compare_digest(given.strip().encode("latin-1", "replace"),
                                                              expected.encode("utf-8"))


def client_identity(expected: str | None, authorization: str | None, address: str | None) -> str:
    """Who submitted a job: a hash of their token when the service has one, else their address."""
    if expected is not None and authorization:
        return "token:" + hashlib.sha256(authorization.partition(" ")[2].strip().encode("latin-1", "replace"))\
            .hexdigest()[:32]
    return f"addr:{address or 'unknown'}"


class TokenFirst:
    """ASGI middleware: 401 ``{"detail": ...}`` with ``WWW-Authenticate: Bearer`` for an unauthenticated request
    to any path but ``/healthz`` and the monitor's static shell, before its body is read."""

    def __init__(self, app, token: str | None):
        self.app = app
        self.token = token

    async def __call__(self, scope, receive, send):
        path = scope.get("path")
        if scope["type"] != "http" or self.token is None or path in PUBLIC_PATHS or is_public(path or ""):
            return await self.app(scope, receive, send)
        header = next((v for k, v in scope.get("headers") or [] if k == b"authorization"), None)
        if bearer_ok(self.token, header.decode("latin-1") if header is not None else None):
            return await self.app(scope, receive, send)
        body = json.dumps({"detail": UNAUTHORIZED}).encode()
        await send({"type": "http.response.start", "status": 401,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"www-authenticate", b"Bearer")]})
        await send({"type": "http.response.body", "body": body})
