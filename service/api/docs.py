"""The error answers each operation documents in OpenAPI: every one is ``{"detail": "<one line>"}``."""
from __future__ import annotations

from schemas import ErrorBody

WHY = {
    400: "malformed request body (e.g. multipart without a boundary)",
    401: "missing or invalid bearer token (only when the service has DRT_API_TOKEN set)",
    404: "no such job, frame or product",
    409: "illegal state change, frame not rendered yet, or the same Idempotency-Key still in progress",
    413: "upload larger than max_upload_bytes",
    422: "invalid input, or a job over the farm's limits (see GET /v1/limits); the detail names the problem",
    503: "the render cluster is unavailable",
}


def errors(*codes: int) -> dict:
    """``responses=`` for a route: each status with the ErrorBody schema and why it happens."""
    return {code: {"model": ErrorBody, "description": WHY[code]} for code in codes}


UNAUTHORIZED_ANSWER = {401: {"model": ErrorBody, "description": WHY[401],
                             "headers": {"WWW-Authenticate": {"description": "Bearer", "schema": {"type": "string"}}}}}
