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
