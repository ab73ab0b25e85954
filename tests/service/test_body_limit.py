"""The request body limit at its exact boundary: limit - 1 and limit bytes pass, limit + 1 is 413, both
when the client declares Content-Length and when it streams the body in chunks without it."""
from __future__ import annotations

import asyncio

import pytest

from service.app import BodyLimit

LIMIT = 100


async def _echo(scope, receive, send):
    body = b""
    while True:
        msg = await receive()
        body += msg.get("body", b"")
        if not msg.get("more_body"):
            break
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": str(len(body)).encode()})


def _call(size: int, declared: bool, chunk: int = 7) -> tuple[int, bytes]:
    data = b"x" * size
    pieces = [data[i:i + chunk] for i in range(0, size, chunk)] or [b""]
    messages = [{"type": "http.request", "body": p, "more_body": i < len(pieces) - 1} for i, p in enumerate(pieces)]
    headers = [(b"content-length", str(size).encode())] if declared else []
    scope = {"type": "http", "method": "POST", "path": "/", "headers": headers}
    sent: list[dict] = []

    async def receive():
        return messages.pop(0)

    async def send(message):
        sent.append(message)

    asyncio.run(BodyLimit(_echo, limit=LIMIT)(scope, receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return status, body


@pytest.mark.parametrize("declared", [True, False])
@pytest.mark.parametrize("size", [0, LIMIT - 1, LIMIT, LIMIT + 1, 3 * LIMIT])
def test_413_exactly_above_the_limit(size, declared):
    status, body = _call(size, declared)
    if size > LIMIT:
        assert status == 413 and str(LIMIT).encode() in body
    else:
        assert status == 200 and body == str(size).encode()
