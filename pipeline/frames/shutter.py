"""The shutter: when within a frame interval each camera sample sees the scene (motion blur).

A frame is an exposure, not an instant: with ``shutter`` s (the share of the frame interval the
shutter is open; 0.5 is film's 180-degree shutter) the camera's samples of a pixel are spread
over the interval s / fps centred on the frame's time, sample j of ``spp`` at the centre of its
stratum, ``(j + 0.5) / spp - 0.5`` of the open time (:func:`shutter_offsets`). Every sample of
index j, in every pixel, sees the scene posed at the same instant, so a frame poses ``spp``
states at most (states whose geometry and lights are the same share their ray caster and
tables); it is the accumulation buffer's motion blur (Haeberli and Akeley, SIGGRAPH 1990) with
the pixel's own samples as the time samples: an object that crosses more than ``spp`` pixels
while the shutter is open shows as ``spp`` faint copies, which more samples a pixel smooth.

The photon maps stay the frame's: indirect light changes slowly (the paper's premise, §1), and its
elements move with the surfaces they lie on, so a sample at another instant reads the map of the
element it hits. The AQM judges unblurred frames (pipeline/segments/halves.py): blur only hides
noise, so its decisions stay on the safe side.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pipeline.scene import FrameState, Scene

MAX_SHUTTER = 1.0  # the whole frame interval: consecutive exposures touch


def shutter_offsets(shutter: float, spp: int) -> np.ndarray:
    """(spp,) float64 time offsets, in frame intervals, of sample j of every pixel: the centres of
    ``spp`` equal strata of ``[-shutter / 2, shutter / 2]``; all zero for an instantaneous shutter."""
    if not 0.0 <= shutter <= MAX_SHUTTER:
        raise ValueError(f"shutter must be in [0, {MAX_SHUTTER}], got {shutter}")
    return shutter * ((np.arange(spp) + 0.5) / spp - 0.5)


def shutter_states(scene: Scene, frame: int, shutter: float, spp: int) -> list[FrameState] | None:
    """The scene as sample j of every pixel of ``frame`` sees it (pipeline/frames/camera_paths.py
    ``render_frame``'s ``shutter_states``); None for an instantaneous shutter or one sample a pixel."""
    if shutter == 0 or spp == 1:
        return None
    t = scene.timeline.time(frame)
    return [scene.pose(t + float(dt) / scene.timeline.fps, frame=frame) for dt in shutter_offsets(shutter, spp)]
