"""The reconstruction task (Dask): Steps 4-5 of §5.2 for a chunk of a segment's frames, from the
photon store to the illumination maps (pipeline/collection/maps.py, pipeline/collection/estimators.py)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pipeline.collection.estimators import frame_geometry, map_digest
from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps
from pipeline.config import RenderConfig
from pipeline.frames.camera_paths import visible_adaptation
from pipeline.frames.settings import RenderSettings
from pipeline.scene.scene_cache import SceneRef
from pipeline.store import PhotonStore, counting_io
from pipeline.store.illumination import IlluminationMaps


@dataclass(frozen=True)
class ReconstructRequest:
    """Steps 4-5 for ``frames`` (consecutive, of one segment) of ``scene``: collected over
    ``windows`` from the first ``batches`` done batches of every store frame, with ``config``'s
    collection, filter and seed; the adaptation pass with the reflections and area samples of
    ``settings``."""

    scene: SceneRef
    store_url: str
    frames: tuple[int, ...]
    windows: WindowSpec
    batches: tuple[int, ...]
    config: RenderConfig
    settings: RenderSettings


def reconstruct_task(request: ReconstructRequest) -> dict:
    """Dask task, Steps 4-5 of §5.2 for the request's frames: the temporal gather of the indirect
    maps (Condition (1) windows up to F_max/2, pipeline/collection/maps.py), the adaptive spatial
    filter where too few photons were collected, each frame's direct estimate from its own photons
    and its adaptation luminance L_wa from what its camera sees of the map it shows
    (pipeline/frames/camera_paths.py visible_adaptation, its paths as the composite's). Writes the
    maps; returns per frame L_wa, a digest of the maps, the vertices filtered and the mean window length."""
    t0 = time.perf_counter()
    config, frames = request.config, request.frames
    scene, elements = request.scene.scene(), request.scene.elements()
    store = PhotonStore.open_shared(request.store_url)
    maps = IlluminationMaps.open_shared(request.store_url, mode="r+")
    use = np.asarray(request.batches, np.int64)
    out = {}
    times = {"setup_s": time.perf_counter() - t0, "adapt_s": 0.0, "map_write_s": 0.0}
    # The direct estimate comes from the batch sums the gather holds (no second read of them)
    with counting_io() as io:  # the sums and counts read, the maps written
        wanted = MapRequest(request.windows, [f - 1 for f in frames], batches=use, direct=True, chunk=len(frames))
        for lit in illumination_maps(store, elements, scene, wanted, config.collection, config.filter, times=times):
            f = lit.frame_index + 1
            t1 = time.perf_counter()
            geometry = frame_geometry(scene, elements, f)  # posed once, by the gather
            indirect, direct = lit.irradiance, lit.direct
            adaptation = visible_adaptation(geometry.state, elements, indirect, request.settings, config.photons.seed)
            t2 = time.perf_counter()
            maps.write_frame(lit.frame_index, indirect=indirect, direct=direct, adaptation=adaptation)
            times["adapt_s"] += t2 - t1
            times["map_write_s"] += time.perf_counter() - t2
            out[str(f)] = {"adaptation": adaptation, "digest": map_digest(indirect),
                           "photons": store.photons_in(lit.frame_index, int(use[lit.frame_index])),
                           "filtered": 0 if lit.rings is None else int(np.count_nonzero(lit.rings)),
                           "window": float(np.mean(lit.back.astype(np.int64) + lit.fwd + 1))}
    return {"frames": out, "seconds": time.perf_counter() - t0,
            "times": {f"reconstruct_{k}": v for k, v in {**times, **io}.items()}}
