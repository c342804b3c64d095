"""The API process's own modules: the HTTP routes (one APIRouter per resource: ``jobs``, ``health``, ``limits``,
``events``, ``monitor``, ``web``), dependencies in ``deps``, the bearer token (``auth``), ``Server-Timing``
(``timing``), the public job view (``presenters``), previews, Prometheus text, and the monitor's static files."""
