"""``drt``, the command line: every command's parser and the one error contract (``main``).

``render`` and ``warmup`` (``render``) need the renderer only; ``serve`` (``serve``) the service's extra; ``submit``,
``status``, ``fetch``, ``cancel``, ``retry`` and ``delete`` (``client``) the client's. Heavy imports (FastAPI,
uvicorn, Dask, httpx, USD, Warp) happen inside the commands that need them, so every command starts fast and
``drt render`` works with the renderer's dependencies alone.
"""
