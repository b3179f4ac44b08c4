"""Built-in scenes, generated procedurally and written as real glTF 2.0 files (``loom scene NAME -o FILE``).

``room`` and ``atrium`` are the paper's two test scenes (§6); ``cornell`` is a small moving scene
for fast tests; ``static`` moves only its camera. Each module's ``build()`` returns a
:class:`GltfBuilder`; its default scene's extras carry ``photonloom`` settings (element_size, fps,
frames).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

from pipeline.errors import LoomError
from pipeline.scene.builtin import atrium, cornell, room, static
from pipeline.scene.builtin.gltf_builder import GltfBuilder

BUILTIN_SCENES: dict[str, Callable[[], GltfBuilder]] = {
    "room": room.build,
    "atrium": atrium.build,
    "cornell": cornell.build,
    "static": static.build,
}


def write_builtin(name: str, path: str | Path) -> Path:
    """Build the built-in scene ``name`` and write it to ``path`` (``.glb`` or ``.gltf``)."""
    try:
        build = BUILTIN_SCENES[name]
    except KeyError:
        choices = ", ".join(sorted(BUILTIN_SCENES))
        raise LoomError(f"unknown built-in scene {name!r}; choose from {choices}", field="scene") from None
    path = Path(path)
    if path.suffix.lower() not in (".glb", ".gltf"):
        raise LoomError("must end in .glb or .gltf", path=str(path), field="--output")
    if path.is_dir():
        raise LoomError("is a directory", path=str(path), field="--output")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # Written under a temporary name and moved into place: a killed run leaves no torn file.
        tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
        build().write(tmp)
        os.replace(tmp, path)
    except OSError as err:
        raise LoomError(f"cannot write: {err.strerror or err}", path=str(path), field="--output") from None
    return path
