"""Request dependencies as ``Annotated`` aliases. Tests swap them with ``app.dependency_overrides``.

They are ``async`` because none of them blocks: FastAPI runs a plain ``def`` dependency on the thread pool, one
hop per dependency per request, which on the status route cost more than the database read itself."""
from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request, Security
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from ..errors import UNAUTHORIZED, ApiError
from ..intake.submission import Inspector, Submitter
from ..queue.store import Store
from ..runtime import Runtime
from ..settings import ServiceSettings
from .auth import CHALLENGE, bearer_ok, client_identity


async def get_settings(request: Request) -> ServiceSettings:
    return request.app.state.settings


async def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


SettingsDep = Annotated[ServiceSettings, Depends(get_settings)]
RuntimeDep = Annotated[Runtime, Depends(get_runtime)]


async def get_store(runtime: RuntimeDep) -> Store:
    return runtime.store


async def get_submitter(runtime: RuntimeDep) -> Submitter:
    return runtime.submitter


async def get_inspector(runtime: RuntimeDep) -> Inspector:
    return runtime.inspector


StoreDep = Annotated[Store, Depends(get_store)]
SubmitterDep = Annotated[Submitter, Depends(get_submitter)]
InspectorDep = Annotated[Inspector, Depends(get_inspector)]


# Declares the bearer scheme in the OpenAPI description; the check itself reads the raw header (as the middleware).
_bearer = HTTPBearer(auto_error=False, description="required when the service has DRT_API_TOKEN set")


async def require_token(settings: SettingsDep, request: Request,
                  _declared: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)] = None) -> None:
    """With ``DRT_API_TOKEN`` set, requests must carry ``Authorization: Bearer <token>``. ``auth.TokenFirst``
    already refused others before their body was read; this dependency documents the scheme and honours
    ``dependency_overrides`` of the settings."""
    if not bearer_ok(_token(settings), request.headers.get("authorization")):
        raise ApiError(401, UNAUTHORIZED, headers=CHALLENGE)


Authorized = Depends(require_token)


def _token(settings: ServiceSettings) -> str | None:
    return settings.api_token.get_secret_value() if settings.api_token is not None else None


async def get_client_id(settings: SettingsDep, request: Request) -> str:
    """The submitter, for the per-client queue limit: its token's hash, else its address."""
    return client_identity(_token(settings), request.headers.get("authorization"),
                           request.client.host if request.client else None)


ClientIdDep = Annotated[str, Depends(get_client_id)]
