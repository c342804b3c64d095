"""Request dependencies as ``Annotated`` aliases. Tests swap them with ``app.dependency_overrides``."""
from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, Header, Request

from ..db import Store
from ..errors import UNAUTHORIZED, ApiError
from ..runtime import Runtime
from ..settings import ServiceSettings
from ..submission import Inspector, Submitter


def get_settings(request: Request) -> ServiceSettings:
    return request.app.state.settings


def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


SettingsDep = Annotated[ServiceSettings, Depends(get_settings)]
RuntimeDep = Annotated[Runtime, Depends(get_runtime)]


def get_store(runtime: RuntimeDep) -> Store:
    return runtime.store


def get_submitter(runtime: RuntimeDep) -> Submitter:
    return runtime.submitter


def get_inspector(runtime: RuntimeDep) -> Inspector:
    return runtime.inspector


StoreDep = Annotated[Store, Depends(get_store)]
SubmitterDep = Annotated[Submitter, Depends(get_submitter)]
InspectorDep = Annotated[Inspector, Depends(get_inspector)]


def require_token(settings: SettingsDep, authorization: Annotated[str | None, Header()] = None) -> None:
    """With ``DRT_API_TOKEN`` set, requests must carry ``Authorization: Bearer <token>``."""
    if settings.api_token is None:
        return
    expected = settings.api_token.get_secret_value()
    scheme, _, given = (authorization or "").partition(" ")
    if scheme.lower() != "bearer" or not secrets.compare_digest(given.strip().encode(), expected.encode()):
        raise ApiError(401, UNAUTHORIZED, headers={"WWW-Authenticate": "Bearer"})


Authorized = Depends(require_token)
