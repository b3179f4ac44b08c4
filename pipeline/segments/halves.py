"""Step 3's measurement (§5.2.3): I1(K) and I2(K), the frame K of the even and of the odd photons
as the viewer sees it, and d_AQM between them (docs/07-segments.md §2).

Both halves are rendered along one set of camera paths with the final frame's direct light
(``render_frame(..., also_maps=...)``: the bits of two renders at the cost of one), at the
adaptation the final frame gets from the map it shows, and tone mapped as it will be
(pipeline/frames/perceived.py)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.aqm.visualize import difference_picture
from pipeline.config import RenderConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame, visible_adaptation
from pipeline.frames.perceived import camera_flow, displayed_difference
from pipeline.frames.settings import RenderSettings

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh, Scene


@dataclass(frozen=True)
class HalvesDifference:
    d_aqm: float  # percent of the pixels where the AQM predicts a visible difference
    picture: np.ndarray  # M_AQM over I1(K) (pipeline/aqm/visualize.py), the record's .aqm.png


def halves_difference(scene: Scene, elements: ElementMesh, halves: np.ndarray, k: int, *,
                      settings: RenderSettings, config: RenderConfig) -> HalvesDifference:
    """d_AQM of frame ``k`` lit by ``halves[0]`` against ``halves[1]`` ((2, V, 3) irradiance, the
    even and odd photons' maps of pipeline/collection/maps.py, ``MapRequest.halves``)."""
    state = scene.pose_frame(k)
    px = settings
    img = render_frame(state, elements, halves[0], CameraPaths.of(px, config.photons.seed, k), also_maps=halves[1:])
    images = [img.beauty, img.also_beauty(0)]
    # L_wa as the frame's own (workers/reconstruct.py): what the camera sees of the halves' mean map
    adaptation = visible_adaptation(state, elements, 0.5 * (halves[0] + halves[1]), px, config.photons.seed)
    flow = camera_flow(scene, k, px.width, px.height, px.tonemap)
    result = displayed_difference(images[0], images[1], adaptation, params=px.tonemap,
                                  aqm_size=config.segments.aqm_size, flow=flow)
    return HalvesDifference(float(result.d_aqm), difference_picture(images[0], result.visible))
