"""Errors the renderer raises for bad input. Their messages are one line and name the problem."""


class RenderError(Exception):
    """Base class: anything the user can fix (bad scene, bad settings)."""


class SceneError(RenderError):
    """The scene file is missing, malformed, or lacks something the render needs."""


class SettingsError(RenderError):
    """A render setting is out of bounds or inconsistent."""


class Cancelled(Exception):
    """The progress callback asked the render to stop."""
