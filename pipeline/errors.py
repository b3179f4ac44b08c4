"""User-facing errors: each one prints as a single line naming the file, the field and the reason.

The CLI catches :class:`LoomError` and exits non-zero with ``str(err)``; anything else is a bug
and keeps its traceback.
"""
from __future__ import annotations


class LoomError(Exception):
    """A problem with the user's input (scene, config, store, options), not a bug."""

    def __init__(self, message: str, *, path: str | None = None, field: str | None = None):
        self.path = path
        self.field = field
        self.reason = message
        parts = [p for p in (path, field) if p]
        prefix = ": ".join(parts)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class SceneError(LoomError):
    """The scene file cannot be loaded as we need it (malformed glTF, unsupported feature, no light...)."""


class ConfigError(LoomError):
    """A parameter is outside its valid range or unknown."""
