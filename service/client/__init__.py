"""The service's client on a user's machine (``drt submit/status/fetch/...``): HTTP only, importable with the
``[client]`` extra alone (no FastAPI, SQLAlchemy or Dask)."""
