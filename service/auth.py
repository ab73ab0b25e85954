"""API keys: the ``X-API-Key`` header, checked against ``GREYBENCH_API_KEYS`` on every route but /health."""
from __future__ import annotations

import hmac

from fastapi import HTTPException, Request, Security
from fastapi.security import APIKeyHeader

HEADER = "X-API-Key"
api_key_header = APIKeyHeader(name=HEADER, auto_error=False, description="an API key from GREYBENCH_API_KEYS")


def key_ok(given: str | None, keys: frozenset[str]) -> bool:
    """Constant-time comparison against every configured key."""
    if not given:
        return False
    ok = False
    for k in keys:
        ok |= hmac.compare_digest(given.encode(), k.encode())
    return ok


def require_key(request: Request, key: str | None = Security(api_key_header)) -> str:
    """FastAPI dependency: 401 without a valid key."""
    if key is None or not key_ok(key, request.app.state.settings.keys()):
        raise HTTPException(status_code=401, detail=f"missing or invalid {HEADER} header",
                            headers={"WWW-Authenticate": HEADER})
    request.state.api_key = key  # the job owner (per-key limits)
    return key
