"""API keys: the ``X-API-Key`` header, checked against ``GREYBENCH_API_KEYS`` (and ``GREYBENCH_ADMIN_KEY``) on
every route but /health. Every job belongs to the key that submitted it: another key gets 404 for it, the
admin key sees, lists and cancels every key's jobs (:func:`may_see`)."""
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


def is_admin(given: str | None, settings) -> bool:
    """``given`` is the configured admin key (constant-time)."""
    return bool(settings.admin_key) and key_ok(given, frozenset({settings.admin_key}))


def may_see(request: Request, job_id: str, owner: str) -> bool:
    """The request may see the job ``job_id`` owned by ``owner`` (:func:`service.jobs.owner_of`): its own key,
    the admin key, or a signed view link of that job (``request.state.view_link``, set by the view routes)."""
    from service.jobs import owner_of

    if getattr(request.state, "view_link", None) == job_id:
        return True
    key = getattr(request.state, "api_key", None)
    if key is None:
        return False
    return is_admin(key, request.app.state.settings) or hmac.compare_digest(owner_of(key), owner)


def require_key(request: Request, key: str | None = Security(api_key_header)) -> str:
    """FastAPI dependency: 401 without a valid key."""
    if key is None or not key_ok(key, request.app.state.settings.keys()):
        raise HTTPException(status_code=401, detail=f"missing or invalid {HEADER} header",
                            headers={"WWW-Authenticate": HEADER})
    request.state.api_key = key  # the job owner (per-key limits)
    return key
