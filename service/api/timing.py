"""``ServerTiming``: every HTTP response tells its client how long the service took to answer it.

The header is the W3C ``Server-Timing`` (``app;dur=<milliseconds>``, shown by browsers' developer tools): the time
from the moment the application receives a request to the moment it starts the response (its status and
headers; a streamed body, such as an EXR download or the monitor's event stream, is not included). Set next to a
client's own figure it tells the service's time from the network's and the client's: ``bench/load_test.py``
prints both. It is measured outermost, so it covers authentication, body limits and the endpoint; it does not
cover uvicorn's parsing of the request or its wait for the event loop before the application is called.
"""
from __future__ import annotations

import time

HEADER = b"server-timing"


class ServerTiming:
    """ASGI middleware adding ``Server-Timing: app;dur=<ms>`` to every HTTP response."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        start = time.perf_counter()

        async def timed(message):
            if message["type"] == "http.response.start":
                ms = (time.perf_counter() - start) * 1e3
                message = {**message, "headers": [*message.get("headers", ()), (HEADER, b"app;dur=%.2f" % ms)]}
            await send(message)

        await self.app(scope, receive, timed)


def app_duration(header: str | None) -> float | None:
    """Seconds from a ``Server-Timing`` value's ``app`` entry (None when it has none)."""
    for entry in (header or "").split(","):
        name, *params = [p.strip() for p in entry.split(";")]
        if name == "app":
            for p in params:
                key, _, value = p.partition("=")
                if key.strip() == "dur":
                    try:
                        return float(value) / 1e3
                    except ValueError:
                        return None
    return None
