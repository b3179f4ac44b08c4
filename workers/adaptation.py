"""A frame's adaptation luminance L_wa from what its camera sees (pipeline/tonemap.py).

A low-resolution pass of the compositor's own camera paths (workers/camera_paths.py render_frame:
direct light by shadow rays, the indirect map at each hit, mirrors and the sky) at
:data:`ADAPTATION_WIDTH` pixels across and one sample a pixel, then the log-average luminance of
the pixels that saw something. Occluded surfaces do not count, and the camera samples are the same
every frame (one fixed random key), so a scene whose light and view do not change gets the same L_wa
in every frame however its objects move in front of the background.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .camera_paths import render_frame

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh, FrameState

ADAPTATION_WIDTH = 64  # pixels across: ~3,000 camera rays, a few ms next to a frame's composite
ADAPTATION_KEY_FRAME = 0  # the random key of every frame's pass (frames count from 1: never a frame's own)


def adaptation_size(aspect: float, width: int = ADAPTATION_WIDTH) -> tuple[int, int]:
    """(width, height) of the pass for an image of ``aspect`` = width / height."""
    return width, max(1, int(round(width / float(aspect))))


def visible_adaptation(state: FrameState, elements: ElementMesh, indirect: np.ndarray, *, aspect: float,
                       seed: int, max_depth: int, area_samples: int, width: int = ADAPTATION_WIDTH) -> float:
    """L_wa (radiance units) of the frame ``state`` lit by the indirect map ``indirect`` (V, 3), as
    its camera sees it: pixels whose paths saw nothing (no geometry, no sky) are left out."""
    from pipeline.tonemap import image_adaptation

    w, h = adaptation_size(aspect, width)
    img = render_frame(state, elements, indirect, width=w, height=h, spp=1, seed=seed,
                       frame=ADAPTATION_KEY_FRAME, max_depth=max_depth, area_samples=area_samples)
    seen = (img.alpha > 0) | (img.beauty.max(axis=-1) > 0)
    return image_adaptation(img.beauty, seen)
