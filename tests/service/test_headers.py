"""Every HTML answer carries Referrer-Policy no-referrer, nosniff and a CSP that allows the service's own
scripts and the page's own inline scripts (by hash) only, and no framing. In process; the pages rendering
under this policy in Chromium are checked by the browser tests of test_view.py and test_view_kinds.py."""
from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

from .conftest import HEADERS, KEY

INDEX = Path(__file__).resolve().parents[2] / "service" / "static" / "view" / "index.html"


def _policy(r) -> dict[str, list[str]]:
    csp = r.headers["content-security-policy"]
    return {d.split()[0]: d.split()[1:] for d in (p.strip() for p in csp.split(";")) if d}


def _inline_hashes(html: str) -> set[str]:
    """The SHA-256 of every inline script of a page, computed here with a plain scan (no regex on tags)."""
    out = set()
    rest = html
    while "<script" in rest:
        rest = rest[rest.index("<script"):]
        tag, rest = rest[:rest.index(">") + 1], rest[rest.index(">") + 1:]
        text, rest = rest[:rest.index("</script>")], rest[rest.index("</script>"):]
        if "src=" not in tag and text.strip():
            out.add("'sha256-" + base64.b64encode(hashlib.sha256(text.encode()).digest()).decode() + "'")
    return out


def _check(r) -> dict[str, list[str]]:
    assert r.headers["content-type"].startswith("text/html"), r.headers
    assert r.headers["referrer-policy"] == "no-referrer"
    assert r.headers["x-content-type-options"] == "nosniff"
    p = _policy(r)
    assert p["frame-ancestors"] == ["'none'"] and p["default-src"] == ["'none'"]
    scripts = p["script-src"]
    assert scripts[0] == "'self'" and set(scripts[1:]) == _inline_hashes(r.text), (scripts, r.text[:300])
    assert not {"'unsafe-inline'", "'unsafe-eval'", "*", "data:", "blob:"} & set(scripts)
    assert p["connect-src"] == ["'self'"] and p["base-uri"] == ["'none'"]
    return p


def test_every_html_answer_of_the_view_carries_the_headers(client):
    from service.jobs import owner_of
    from service.states import JobKind

    store = client.app.state.store
    queued = store.create(JobKind.simulation, {}, "b", owner=owner_of(KEY)).id
    pages = [client.get(f"/simulations/{queued}/view"),                       # the key form (401)
             client.get(f"/simulations/{queued}/view", headers=HEADERS),      # not finished (409)
             client.get(f"/simulations/{'a' * 32}/view", headers=HEADERS),    # unknown (404)
             client.get(f"/circles/{queued}/view", headers=HEADERS)]          # another kind's id (404)
    assert [r.status_code for r in pages] == [401, 409, 404, 404]
    for r in pages:
        _check(r)
    # the key form is the page itself: its one inline script (the import map) is allowed by its hash
    assert len(_inline_hashes(pages[0].text)) == 1
    index = INDEX.read_text()
    importmap = re.search(r'<script type="importmap">(.*?)</script>', index, re.S).group(1)
    expected = "'sha256-" + base64.b64encode(hashlib.sha256(importmap.encode()).digest()).decode() + "'"
    assert _policy(pages[0])["script-src"] == ["'self'", expected]
    # the notices have no script at all
    assert _policy(pages[1])["script-src"] == ["'self'"]


def test_docs_pages_carry_the_headers_and_json_stays_plain(client):
    for url in ("/docs", "/redoc"):
        r = client.get(url)
        assert r.status_code == 200
        _check(r)
    docs = client.get("/docs")
    assert len(_policy(docs)["script-src"]) >= 2     # Swagger UI's start script is inline: allowed by its hash
    r = client.get("/health")
    assert r.headers["content-type"].startswith("application/json")
    assert "content-security-policy" not in r.headers


def test_inline_script_hashes_follow_the_content():
    from service.headers import content_security_policy, script_hashes

    page = b"<html><script>alert(1)</script><script src=/x.js></script><SCRIPT type=module>b()</SCRIPT></html>"
    expected = ["'sha256-" + base64.b64encode(hashlib.sha256(t).digest()).decode() + "'" for t in (b"alert(1)", b"b()")]
    assert script_hashes(page) == expected
    assert script_hashes(page.replace(b"alert(1)", b"alert(2)")) != expected
    assert script_hashes(b"<script src='/a.js'></script><script> </script>") == []
    assert "script-src 'self' 'sha256-a'" in content_security_policy(["'sha256-a'"])
