"""The frame stage (§3, §6): ray-traced direct and specular light per pixel, indirect from the map.

For every pixel, ``spp`` jittered camera rays. At each hit:

* an emitter seen from its front face shows its emitted radiance (times its emissive texture);
* a **diffuse** surface gets direct light from every light with shadow rays (point, spot and
  directional exactly; emissive triangles by ``area_samples`` samples chosen by power, i.e. area x
  radiance; a sky, pipeline/scene/sky.py, by ``area_samples`` cosine-weighted directions) and
  indirect radiance rho/pi x E, E interpolated inside the hit element from its three
  vertex irradiances (the illumination map, workers/reconstruct.py); the path ends there;
* Lambert cosines, reflections and lobes use the shading normal (vertex normals), sidedness and
  ray offsets the geometric one; the albedo is the hit's base colour (factor x texture x COLOR_0),
  per sample, so textures are resolved per pixel (pipeline/scene/shading.py);
* with a shutter (``RenderSettings.shutter``), sample j of every pixel sees the scene and the camera
  posed at its own instant of the open shutter: motion blur (pipeline/frames/shutter.py);
* a ray that leaves the scene shows the sky's radiance, if there is a sky (coverage stays 0);
* a **mirror** reflects, a **glossy** surface samples its normalised Phong lobe (the photon tracer's
  lobe, pipeline/scene/materials.py) and gets exact highlights of punctual lights; both continue up
  to ``max_depth`` reflections. Area lights reach glossy surfaces through the lobe samples only.

Layers per pixel (linear, radiance units): ``direct`` (emission and direct light, through the
specular chain), ``indirect`` (the map term), beauty = direct + indirect, and ``albedo`` of the
first surface hit. Ray counts per kind: camera, shadow (punctual lights), area (area-light and sky
shadow rays), reflection. Scenes without specular materials cast no reflection rays, scenes without
emissive triangles no area rays.

Determinism: every random number is a hash of (seed, frame, pixel, sample, dimension)
(splitmix64, Steele et al., OOPSLA 2014), so pixels do not depend on chunking or workers.

The stage in parts: pipeline/frames/camera_paths.py (the path loop and the frame), pipeline/frames/camera_hits.py
(hit records), pipeline/frames/shading_tables.py (per-frame lookups), pipeline/frames/punctual_lights.py,
pipeline/frames/area_lights.py (emissive triangles and the sky), pipeline/frames/random_numbers.py.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from pipeline.frames.camera_paths import CameraPaths, render_exposure, render_frame
from pipeline.frames.images import frame_paths, write_exr, write_png
from pipeline.frames.settings import RenderSettings
from pipeline.frames.shutter import shutter_states
from pipeline.frames.tonemap import tonemap as tone
from pipeline.scene.scene_cache import SceneRef
from pipeline.store.illumination import IlluminationMaps


@dataclass(frozen=True)
class CompositeRequest:
    """Frame ``frame`` of ``scene`` with its indirect map from the store at ``store_url``, rendered
    and tone mapped as ``settings`` say at the eye's adaptation L_a ``adaptation``
    (pipeline/frames/tonemap.py), its random numbers keyed by ``seed``; its EXR and PNG written to
    ``out_dir``, the EXR carrying ``metadata``."""

    scene: SceneRef
    store_url: str
    frame: int
    settings: RenderSettings
    seed: int
    adaptation: float
    out_dir: str
    metadata: dict


def composite_task(request: CompositeRequest) -> dict:
    """Dask task: render one frame, tone-map it and write its EXR and PNG (atomically).

    A frozen request in, a small dict of timings and ray counts out.
    """
    t0 = time.perf_counter()
    frame = request.frame
    scene, elements = request.scene.scene(), request.scene.elements()
    state = scene.pose_frame(frame)
    irradiance = IlluminationMaps.open_shared(request.store_url).read(frame - 1, "indirect")
    t1 = time.perf_counter()
    settings = request.settings
    paths = CameraPaths.of(settings, request.seed, frame)
    blur = shutter_states(scene, frame, settings.shutter, settings.spp)
    img = (render_frame(state, elements, irradiance, paths) if blur is None
           else render_exposure(state, blur, elements, irradiance, paths))
    t2 = time.perf_counter()
    exr, png = frame_paths(request.out_dir, frame)
    write_exr(exr, img.beauty, img.alpha, {"direct": img.direct, "indirect": img.indirect,
                                           "albedo": img.albedo}, {**request.metadata, "frame": frame})
    write_png(png, tone(img.beauty, request.adaptation, request.settings.tonemap))
    t3 = time.perf_counter()
    return {"frame": frame, "rays": img.rays, "load_s": t1 - t0, "render_s": t2 - t1,
            "write_s": t3 - t2}
