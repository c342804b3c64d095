"""Errors the service answers with, and their stable ``detail`` strings (clients and tests match on them).

Service modules raise ``ApiError(status, detail)`` without knowing about FastAPI; the app turns it into
``{"detail": ...}`` with that status.
"""
from __future__ import annotations

JOB_NOT_FOUND = "job not found"
FRAME_NOT_FOUND = "frame not found"
FRAME_NOT_READY = "frame is not rendered yet"
BAD_CURSOR = "invalid cursor"
UNAUTHORIZED = "missing or invalid bearer token"
IDEMPOTENCY_MISMATCH = "Idempotency-Key was already used with a different request"
IDEMPOTENCY_BUSY = "a request with this Idempotency-Key is still being processed"
CLUSTER_UNAVAILABLE = "the render cluster is unavailable"


def product_not_found(frame: str, name: str, names: list[str]) -> str:
    return f"frame {frame} has no product {name!r} (its products: {', '.join(names) or 'none'})"


def bad_product_name(name: str) -> str:
    return f"not a product name: {name!r} (a relative path inside the job, without '..')"


def cannot_cancel(state: str) -> str:
    return f"cannot cancel a {state} job"


def cannot_retry(state: str) -> str:
    return f"cannot retry a {state} job; only failed or canceled jobs can be retried"


def cannot_delete(state: str) -> str:
    return f"cannot delete a {state} job; cancel it first"


class ApiError(Exception):
    def __init__(self, status: int, detail: str, headers: dict[str, str] | None = None):
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.headers = headers
