"""``loom bench frame``: compositor milliseconds per frame, and its rays/s against raw embreex.

For each scene (the built-in ROOM and ATRIUM, or the files given), one frame from the middle of
the timeline is rendered at the given resolution and spp in this process, pinned to one core.
The indirect map is a constant (the compositor's cost does not depend on its values). Raw
embreex speed is measured in the same run on the same triangles: the frame's pixel-centre camera
rays, cast in one ``EmbreeScene.run`` call, alternating with the compositor's renders. The compositor's
rays/s counts every ray it casts
(camera, shadow, area, reflection) over the whole frame time, so the ratio is the cost of
everything that is not Embree. Target: at least 50 % of raw.
"""
from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np
from embreex import mesh_construction, rtcore_scene

from kernels.camera import camera_rays_reference
from pipeline.frames.camera_paths import CHUNK_RAYS, CameraPaths, render_frame
from pipeline.photons.raycast import caster_for
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import BUILTIN_SCENES, write_builtin

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from pipeline.scene import FrameState


def _raw_caster(state: FrameState, width: int, height: int) -> Callable[[], None]:
    """A function casting the frame's pixel-centre camera rays through embreex alone, once."""
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, np.ascontiguousarray(state.vertices, np.float32),
                                   np.ascontiguousarray(state.faces, np.int32))
    cam = state.camera  # the compositor's own jittered camera rays, one a pixel
    d = camera_rays_reference(0, 0, width * height, 1, width, height, cam.definition.yfov, cam.to_world[:3, :3])
    origin = cam.position
    o = np.ascontiguousarray(np.broadcast_to(origin, d.shape), np.float32)
    d = np.ascontiguousarray(d, np.float32)
    scene.run(o[:1], d[:1])  # commit the BVH
    def cast() -> None:  # in the compositor's batch size, which Embree runs faster than one huge batch
        for lo in range(0, len(d), CHUNK_RAYS):
            scene.run(o[lo:lo + CHUNK_RAYS], d[lo:lo + CHUNK_RAYS], output=1)
    return cast


def bench_scene(path: str | Path, *, width: int, height: int, spp: int, repeat: int) -> dict:
    """Figures for one scene: ms/frame, rays per kind, compositor and raw rays/s.

    Compositor and raw casts alternate, ``repeat`` times each, so both see the same machine load;
    the figures are medians, the ratio the median of the paired ratios.
    """
    scene = read_scene(path)
    frame = (scene.timeline.first + scene.timeline.last) // 2
    state = scene.pose_frame(frame)
    elements = ElementMesh.build(scene)
    irradiance = np.full((elements.n_vertices, 3), 0.5)
    caster = caster_for(state)
    paths = CameraPaths(width, height, spp, 0, frame)
    img = render_frame(state, elements, irradiance, paths, caster=caster)  # warm-up
    raw_cast = _raw_caster(state, width, height)
    frame_s, raw_s = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        img = render_frame(state, elements, irradiance, paths, caster=caster)
        t1 = time.perf_counter()
        raw_cast()
        frame_s.append(t1 - t0)
        raw_s.append(time.perf_counter() - t1)
    rays = sum(img.rays.values())
    n_raw = width * height
    ratio = statistics.median((rays / f) / (n_raw / r) for f, r in zip(frame_s, raw_s))
    seconds = statistics.median(frame_s)
    return {"scene": Path(path).stem, "frame": frame, "ms": seconds * 1e3, "rays": img.rays,
            "rays_per_s": rays / seconds, "raw_rays_per_s": n_raw / statistics.median(raw_s),
            "ratio": ratio}


def run(scenes: Iterable[str], *, width: int, height: int, spp: int, repeat: int,
        echo: Callable[[str], None] = click.echo) -> list[dict]:
    """Benchmark ``scenes`` (built-in names or files; default ROOM and ATRIUM) on one core, echoing a
    line per scene; returns their figures."""
    results = []
    pinned = hasattr(os, "sched_setaffinity")
    if pinned:  # one core for both measurements, like one Dask worker
        cores = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(cores)})
    try:
        with tempfile.TemporaryDirectory() as tmp:
            # Scene files, or names of built-in scenes (as `loom bench photons` takes them)
            paths = [write_builtin(n, Path(tmp) / f"{n}.glb") if n in BUILTIN_SCENES else n
                     for n in (list(scenes) or ["room", "atrium"])]
            echo(f"compositor at {width}x{height}, {spp} spp, one core, median of {repeat}")
            for path in paths:
                r = bench_scene(path, width=width, height=height, spp=spp, repeat=repeat)
                results.append(r)
                kinds = ", ".join(f"{k} {v:,}" for k, v in r["rays"].items())
                echo(f"{r['scene']:>8} frame {r['frame']}: {r['ms']:7.1f} ms/frame  "
                     f"{r['rays_per_s'] / 1e6:5.2f} Mrays/s vs raw embreex "
                     f"{r['raw_rays_per_s'] / 1e6:5.2f} Mrays/s ({100 * r['ratio']:.0f} %)  [{kinds}]")
    finally:
        if pinned:
            os.sched_setaffinity(0, cores)
    return results
