"""Step 3's measurement (§5.2.3): I1(K) and I2(K), the frame K of the even and of the odd photons
as the viewer sees it, and d_AQM between them (docs/07-segments.md §2).

Both halves light one set of camera paths with the final frame's direct light, at the adaptation
the final frame gets from the map it shows, and are tone mapped as it will be
(pipeline/frames/perceived.py). The paths never depend on the map, so :class:`HalvesJudge` traces a
frame's paths once, keeping where they read the map (pipeline/frames/map_hits.py), and lights them
with every later pair of halves at that frame: Step 3's doublings and the windows' F_max tries
judge one K again and again, and each judgement gets the bits of rendering both halves anew."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.aqm.visualize import difference_picture
from pipeline.config import RenderConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame, visible_adaptation
from pipeline.frames.map_hits import hits_bytes
from pipeline.frames.perceived import camera_flow, displayed_difference
from pipeline.frames.settings import RenderSettings

if TYPE_CHECKING:
    from pipeline.frames.map_hits import MapHits
    from pipeline.scene import ElementMesh, Scene


@dataclass(frozen=True)
class HalvesDifference:
    d_aqm: float  # percent of the pixels where the AQM predicts a visible difference
    picture: np.ndarray  # M_AQM over I1(K) (pipeline/aqm/visualize.py), the record's .aqm.png


@dataclass(frozen=True)
class _TracedFrame:
    """What a frame's judgements share: its direct light, where its paths read the map, its flow."""

    frame: int
    direct: np.ndarray
    hits: MapHits
    flow: np.ndarray | None


KEPT_BYTES = 1 << 30  # the most the judge keeps of a frame's paths (a 1920x1080 frame at 8 spp takes 730 MB)


class HalvesJudge:
    """d_AQM of the halves at a frame, the last frame's camera paths kept for the next judgement
    while they take at most ``kept_bytes`` (larger frames are traced for every judgement)."""

    def __init__(self, scene: Scene, elements: ElementMesh, *, settings: RenderSettings, config: RenderConfig,
                 kept_bytes: int = KEPT_BYTES):
        self.scene, self.elements, self.settings, self.config = scene, elements, settings, config
        self.kept_bytes = kept_bytes
        self._traced: _TracedFrame | None = None
        self.traced_frames = 0  # how many times paths were traced (the rest were relit)

    def difference(self, halves: np.ndarray, k: int) -> HalvesDifference:
        """d_AQM of frame ``k`` lit by ``halves[0]`` against ``halves[1]`` ((2, V, 3) irradiance, the
        even and odd photons' maps of pipeline/collection/maps.py, ``MapRequest.halves``)."""
        px, el = self.settings, self.elements
        state = self.scene.pose_frame(k)
        if self._traced is not None and self._traced.frame == k:
            t = self._traced
            images, flow = [t.direct + t.hits.indirect(el, h) for h in halves[:2]], t.flow
        else:
            paths = CameraPaths.of(px, self.config.photons.seed, k)
            img = render_frame(state, el, halves[0], paths, also_maps=halves[1:2],
                               record_hits=hits_bytes(paths.width * paths.height * paths.spp) <= self.kept_bytes)
            images = [img.beauty, img.also_beauty(0)]
            flow = camera_flow(self.scene, k, px.width, px.height, px.tonemap)
            self._traced = None if img.map_hits is None else _TracedFrame(k, img.direct, img.map_hits, flow)
            self.traced_frames += 1
        # L_wa as the frame's own (workers/reconstruct.py): what the camera sees of the halves' mean map
        adaptation = visible_adaptation(state, el, 0.5 * (halves[0] + halves[1]), px, self.config.photons.seed)
        result = displayed_difference(images[0], images[1], adaptation, params=px.tonemap,
                                      aqm_size=self.config.segments.aqm_size, flow=flow)
        return HalvesDifference(float(result.d_aqm), difference_picture(images[0], result.visible))
