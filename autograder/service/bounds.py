"""Request bounds: every request body is counted as it arrives and refused at its limit.

Starlette reads a form whole (a urlencoded form into memory, a multipart file
into a temporary file), and uvicorn has no body limit at all; neither knows
which route is an upload. :class:`BodyLimit` is a small ASGI middleware written
here for that: it wraps ``receive`` so that the route's parser sees the body
chunk by chunk and gets :class:`RequestTooLarge` (a 413) the moment the count
passes the route's limit - or before the first byte when ``Content-Length``
announces more. A chunked body without ``Content-Length`` is held to the same
count. An answer given before the whole body was read (too large, or refused
for another reason such as the hourly limit) carries ``Connection: close``, so
the server stops reading the rest of the body instead of draining it.

Only a student's upload may be large (the course's ``max_upload_bytes`` plus a
little for the form around it); every other request, the sign-in form included,
is held to :data:`~autograder.service.settings.FORM_BYTES`.
"""

from __future__ import annotations

import re
from typing import Any, Awaitable, Callable, MutableMapping

from fastapi import HTTPException

from autograder.service.settings import FORM_BYTES, UPLOAD_FORM_SLACK

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

UPLOAD_PATH = re.compile(r"/assignments/[^/]+/submissions")
CLOSE = (b"connection", b"close")


class RequestTooLarge(HTTPException):
    """A request body passed its limit; nothing of it was used."""

    def __init__(self, limit: int, *, upload: bool) -> None:
        self.limit, self.upload = limit, upload
        if upload:
            message = (f"The upload is larger than {limit / 1e6:.1f} MB, more than uploads may be; "
                       "nothing was stored. Clear the notebook's outputs (Kernel > Restart & "
                       "Clear Output) and upload it again.")
        else:
            message = (f"This request is larger than {limit // 1024} KB, more than any form of "
                       "this site sends; it was not read. Reload the page and try again.")
        super().__init__(413, message)


def is_upload(scope: Scope) -> bool:
    return scope.get("method") == "POST" and UPLOAD_PATH.fullmatch(scope.get("path", "")) is not None


def upload_limit(max_upload_bytes: int) -> int:
    """The body limit of an upload form holding a notebook of at most ``max_upload_bytes``."""
    return max_upload_bytes + UPLOAD_FORM_SLACK


def announced_length(scope: Scope) -> int | None:
    """The ``Content-Length`` of the request (uvicorn has checked it is a number), if any."""
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            text = value.decode("latin-1").strip()
            return int(text) if text.isdigit() else None
    return None


class BodyLimit:
    """ASGI middleware: the body of ``/assignments/*/submissions`` is bounded by the course's
    upload limit, every other body by ``FORM_BYTES``; past the limit the route gets a 413."""

    def __init__(self, app: ASGIApp, *, max_upload_bytes: int) -> None:
        self.app = app
        self.upload_bytes = upload_limit(max_upload_bytes)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        upload = is_upload(scope)
        limit = self.upload_bytes if upload else FORM_BYTES
        announced = announced_length(scope)
        has_body = (announced or 0) > 0 or any(n == b"transfer-encoding" for n, _ in scope["headers"])
        seen = 0
        over = False
        started = False
        read_all = not has_body

        async def bounded_receive() -> Message:
            nonlocal seen, over, read_all
            if over or (announced is not None and announced > limit):
                over = True
                raise RequestTooLarge(limit, upload=upload)
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    over = True
                    raise RequestTooLarge(limit, upload=upload)
                read_all = read_all or not message.get("more_body", False)
            return message

        async def closing_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
                if over or not read_all:  # never read (or drain) the rest of a body we refused
                    headers = [h for h in message.get("headers", ()) if h[0].lower() != b"connection"]
                    message = {**message, "headers": [*headers, CLOSE]}
            await send(message)

        try:
            await self.app(scope, bounded_receive, closing_send)
        except RequestTooLarge as exc:  # raised where no handler turned it into a page
            if started:
                raise
            await closing_send({"type": "http.response.start", "status": 413,
                                "headers": [(b"content-type", b"text/plain; charset=utf-8")]})
            await closing_send({"type": "http.response.body", "body": str(exc.detail).encode()})
