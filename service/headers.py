"""Security headers on every HTML answer (the planner's page, its notices, /docs, /redoc).

The view page carries its signed token in the URL, so no page may send it on as a referrer
(``Referrer-Policy: no-referrer``), be framed by another site (``frame-ancestors 'none'``) or run a script
that is not its own: the Content-Security-Policy allows scripts from the service itself and the page's
own inline scripts by their SHA-256 (the view page's import map, Swagger UI's start script), nothing
else, no ``eval``. Styles may be inline (the page colours table cells with ``style`` attributes), images
come from the service, ``data:`` (the empty favicon, Swagger's icons) or ``blob:``; ``connect-src 'self'``
for the page's own requests; ``worker-src blob:`` for ReDoc's search worker. ``X-Content-Type-Options:
nosniff`` everywhere HTML is sent.
"""
from __future__ import annotations

import base64
import hashlib
import re

#: Largest HTML body whose inline scripts are hashed [bytes]; larger pages get no inline script.
MAX_HTML_BYTES = 4 * 1024 * 1024
#: An inline script: a ``<script>`` without ``src``, its text.
_INLINE = re.compile(rb"<script(?![^>]*\bsrc\s*=)[^>]*>(.*?)</script\s*>", re.IGNORECASE | re.DOTALL)

STATIC_HEADERS = {"Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff"}


def script_hashes(html: bytes) -> list[str]:
    """CSP sources (``'sha256-...'``) of the inline scripts of ``html``, in order, without repeats."""
    out: list[str] = []
    for m in _INLINE.finditer(html):
        if not m.group(1).strip():
            continue
        digest = base64.b64encode(hashlib.sha256(m.group(1)).digest()).decode()
        src = f"'sha256-{digest}'"
        if src not in out:
            out.append(src)
    return out


def content_security_policy(hashes: list[str]) -> str:
    """The policy of an HTML answer whose own inline scripts have ``hashes``."""
    scripts = " ".join(["'self'", *hashes])
    return (f"default-src 'none'; script-src {scripts}; style-src 'self' 'unsafe-inline'; "
            "img-src 'self' data: blob:; connect-src 'self'; font-src 'self' data:; worker-src 'self' blob:; "
            "base-uri 'none'; form-action 'self'; frame-ancestors 'none'")


class HtmlHeaders:
    """ASGI middleware: adds :data:`STATIC_HEADERS` and the CSP of :func:`content_security_policy` to every
    ``text/html`` answer (the body is read to hash its inline scripts; a compressed one gets no hashes)."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        start: dict = {}
        chunks: list[bytes] = []
        mode = "wait"   # -> "pass" (not HTML, or HTML already started), "html" (buffering the page)

        async def send_html(message):
            nonlocal start, mode
            if message["type"] == "http.response.start":
                ctype = dict(message.get("headers", [])).get(b"content-type", b"")
                mode = "html" if ctype.lower().startswith(b"text/html") else "pass"
                if mode == "pass":
                    await send(message)
                else:
                    start = message
                return
            if mode != "html" or message["type"] != "http.response.body":
                await send(message)
                return
            chunks.append(message.get("body", b""))
            size = sum(len(c) for c in chunks)
            if message.get("more_body", False) and size <= MAX_HTML_BYTES:
                return
            body = b"".join(chunks)
            chunks.clear()
            headers = [(k, v) for k, v in start.get("headers", []) if k.lower() != b"content-security-policy"]
            plain = not any(k.lower() == b"content-encoding" for k, _ in headers) and size <= MAX_HTML_BYTES
            csp = content_security_policy(script_hashes(body) if plain else [])
            headers += [(k.lower().encode(), v.encode()) for k, v in STATIC_HEADERS.items()]
            headers.append((b"content-security-policy", csp.encode()))
            await send({**start, "headers": headers})
            mode = "pass"   # the rest of a large body streams through
            await send({**message, "body": body})

        await self.app(scope, receive, send_html)
