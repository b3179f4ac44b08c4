"""The writable-location check of every output the CLI is given (``--out``, ``--store``)."""
from __future__ import annotations

import os
from pathlib import Path

from .errors import LoomError


def check_writable_dir(path: Path | str, *, field: str) -> None:
    """Refuse a directory location that is a file or cannot be written, before any work: one
    LoomError naming the path and the option ``field`` it came from. A location that does not
    exist yet is judged by its nearest existing ancestor (it will be created there)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise LoomError("exists and is not a directory", path=str(path), field=field)
    parent = path
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise LoomError(f"is not writable ({parent} does not allow writing)", path=str(path), field=field)
