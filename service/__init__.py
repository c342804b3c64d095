"""The render service: HTTP API (FastAPI), a persistent job queue (SQLite), tiled rendering on Dask.

Dependency direction: ``service -> renderer`` and ``service -> schemas``; the renderer knows nothing of HTTP,
pydantic or the queue.
"""
