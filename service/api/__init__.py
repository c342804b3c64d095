"""HTTP routes: one APIRouter per resource (``jobs``, ``health``), dependencies in ``deps``."""
