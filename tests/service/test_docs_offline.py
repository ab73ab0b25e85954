"""/docs and /redoc work without internet: the pages reference no external host, and every asset
they load is served by the app itself (from the fastapi-offline package)."""
import re

import pytest

REF = re.compile(r"""(?:src|href|spec-url)\s*=\s*["']([^"']+)["']|url:\s*'([^']+)'""")


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_docs_pages_reference_no_external_host(client, page):
    r = client.get(page)
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]
    html = r.text
    assert not re.search(r"(?:https?:)?//[A-Za-z0-9.-]+", html.replace("window.location.origin", "")), html
    refs = [a or b for a, b in REF.findall(html)]
    assert len(refs) >= 3, refs  # stylesheet/script, favicon, the OpenAPI document
    for ref in refs:
        assert ref.startswith("/"), ref
        asset = client.get(ref)
        assert asset.status_code == 200, ref
        if ref.endswith(".js"):
            assert len(asset.content) > 100_000, ref  # the real bundle, not a stub


def test_swagger_validator_badge_is_off(client):
    # Swagger UI's default validator is a public web service
    assert '"validatorUrl": null' in client.get("/docs").text
