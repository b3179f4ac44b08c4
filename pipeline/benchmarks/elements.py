"""``loom bench elements``: what the element mesh's size costs in the frames, against a finer mesh.

The indirect light is as fine as the elements that collect it (§5.3): a vertex holds the photons of
its elements' hat function, so lighting that bends inside an element is flattened. The error
benchmark cannot see that bias, since its reference shares the render's elements
(docs/12-error-benchmark.md §2). Here, for each frame, the indirect map is converged (``photons``
a frame, :func:`pipeline.benchmarks.error.reference_map`, no temporal collection) on meshes of
element size ``scale`` x the scene's, and every map lights the same camera paths
(pipeline/frames/camera_paths.py): the frames differ only by the mesh. Each is compared with the
finest mesh's frame as the viewer sees it (d_AQM, FLIP, relative RMS of luminance); a second seed on
the finest mesh is the floor, the photons' own noise. The finest mesh has a bias of its own, which
no row shows: the figures are what a coarser mesh adds.

Fewer, larger elements each collect more photons: at a given N_frame a vertex's photon-noise
variance is proportional to the elements' count (photons an element ~ 1 / elements), which is the
lever of coarser elements; the table prints the count beside the bias it costs. Decision
(:func:`coarsest_invisible_scale`): the coarsest scale whose frames are within d_thr of the finest
on every frame, i.e. whose bias is no more visible than the photon noise the guided default accepts;
none when the floor itself is over d_thr (the maps are not converged: more photons are needed).
Writes ``OUT/elements.json`` and ``OUT/elements.png`` (per frame: the finest mesh's frame, then each
scale's luminance difference from it, red brighter, blue darker, full scale +-10 % of the mean).
"""
from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from pipeline.config import RenderConfig
from pipeline.errors import LoomError
from pipeline.frames.camera_paths import CameraPaths, render_frame, visible_adaptation
from pipeline.frames.images import write_png
from pipeline.frames.perceived import displayed_difference
from pipeline.frames.settings import RenderSettings
from pipeline.run.cluster import connect
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import BUILTIN_SCENES, write_builtin

from .error import REFERENCE_SEEDS, reference_map
from .error_measures import LUMA, flip_mean, frame_ppd, relative_rms, shown

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

FRAMES = (23, 68, 113)  # ROOM's segment centres K (§6, Table 1)
SCALES = (0.5, 0.75, 1.0, 1.5)  # element sizes as multiples of the scene's; the smallest is the comparison
DIFFERENCE_SCALE = 0.1  # elements.png: a luminance difference of 10 % of the frame's mean is full colour


def coarsest_invisible_scale(rows: Sequence[dict], threshold: float, key: str = "d_aqm") -> float | None:
    """The largest ``scale`` of ``rows`` (dicts with "scale", "frame" and ``key``) such that it and every
    finer scale have ``key`` <= ``threshold`` on every frame; None if even the finest compared fails."""
    scales = sorted({float(r["scale"]) for r in rows})
    worst = {s: max(float(r[key]) for r in rows if float(r["scale"]) == s) for s in scales}
    best = None
    for s in scales:
        if worst[s] > threshold:
            break
        best = s
    return best


def difference_picture(test: np.ndarray, ref: np.ndarray, full_scale: float = DIFFERENCE_SCALE) -> np.ndarray:
    """(H, W, 3) uint8: the luminance difference of ``test`` from ``ref`` over ``ref``'s mean luminance,
    red where ``test`` is brighter, blue where darker, full colour at ``full_scale``."""
    y_ref = ref @ LUMA
    d = (test @ LUMA - y_ref) / max(float(np.mean(y_ref)), 1e-30) / full_scale
    rgb = np.zeros(ref.shape, np.float64)
    rgb[..., 0] = np.clip(d, 0.0, 1.0)
    rgb[..., 2] = np.clip(-d, 0.0, 1.0)
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def _maps(client, scene, path: Path, sizes: Sequence[float], frame: int, photons: int, depth: int) -> list:
    """Converged maps of ``frame``: one per element size with the first seed, then the finest with
    the second; traced on the cluster's workers, or here without one."""
    jobs = [(size, REFERENCE_SEEDS[0]) for size in sizes] + [(sizes[0], REFERENCE_SEEDS[1])]
    kwargs = [dict(scene_path=str(path.resolve()), scene_hash=scene.scene_hash, element_size=size, frame=frame,
                   n_photons=photons, seed=seed, stream=frame, max_depth=depth) for size, seed in jobs]
    if client is None:
        return [reference_map(**k) for k in kwargs]
    return client.gather([client.submit(reference_map, **k, pure=False) for k in kwargs])


def run(scene_name: str = "room", *, frames: Sequence[int] = FRAMES, scales: Sequence[float] = SCALES,
        photons: int = 16_000_000, width: int = 320, height: int = 240, spp: int | None = None,
        element_size: float | None = None, scheduler: str = "local", workers: int = 2, out_dir: Path | None = None,
        echo: Callable[[str], None] = click.echo) -> dict:
    """Measure, print the table, write ``elements.json`` and ``elements.png`` in ``out_dir``; the scales
    multiply ``element_size`` (default the scene's own)."""
    config = RenderConfig()
    settings = RenderSettings(width=width, height=height, **({} if spp is None else {"spp": spp}))
    thr = 100.0 * config.segments.d_thr
    scales = sorted({float(s) for s in scales})
    if len(scales) < 2 or scales[0] <= 0:
        raise LoomError(f"give at least two positive scales, got {scales}", field="--scales")
    out_dir = Path(out_dir or f"bench-elements-{Path(scene_name).stem}")
    ppd = frame_ppd(width, height)
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="loom-bench-elements-") as tmp:
        path = (write_builtin(scene_name, Path(tmp) / f"{scene_name}.glb") if scene_name in BUILTIN_SCENES
                else Path(scene_name))
        scene = read_scene(path)
        bad = [f for f in frames if not scene.timeline.first <= f <= scene.timeline.last]
        if bad:
            raise LoomError(f"frame(s) {bad} are not inside the scene's {scene.timeline.first}-"
                            f"{scene.timeline.last}", path=str(path), field="--frames")
        if element_size is not None and not element_size > 0:
            raise LoomError(f"must be positive, got {element_size}", field="--element-size")
        base = ElementMesh.build(scene, element_size).element_size
        sizes = [base * s for s in scales]
        meshes = [ElementMesh.build(scene, size) for size in sizes]
        echo(f"loom bench elements {Path(path).stem}: frames {', '.join(map(str, frames))}, {width}x{height}, "
             f"{settings.spp} spp, {ppd:.1f} pixels/degree; converged maps of {photons:,} photons a frame on "
             f"element sizes {', '.join(f'{s:g}' for s in sizes)} ({', '.join(f'{m.n_elements:,}' for m in meshes)}"
             f" elements), each against the finest; d_thr = {thr:g} %")
        rows, floors, pictures = [], [], []
        with connect(scheduler, workers) as client:
            for frame in frames:
                t0 = time.perf_counter()
                echo(f"frame {frame}: tracing {len(sizes) + 1} maps of {photons:,} photons ...")
                maps = _maps(client, scene, path, sizes, frame, photons, config.photons.photon_depth)
                state = scene.pose_frame(frame)
                paths = CameraPaths.of(settings, config.photons.seed, frame)
                images = [render_frame(state, mesh, m.astype(np.float32), paths).beauty
                          for mesh, m in zip([*meshes, meshes[0]], maps)]
                ref, alt = images[0], images[-1]
                adaptation = visible_adaptation(state, meshes[0], maps[0].astype(np.float32), settings,
                                                config.photons.seed)

                def measure(img, ref=ref, adaptation=adaptation) -> dict:
                    return dict(d_aqm=float(displayed_difference(img, ref, adaptation).d_aqm),
                                flip=flip_mean(shown(img, adaptation), shown(ref, adaptation), ppd),
                                rel_rms=relative_rms(img, ref))

                floors.append(dict(frame=frame, **measure(alt)))
                echo(f"frame {frame} ({time.perf_counter() - t0:.0f} s): floor (element size {sizes[0]:g}, another "
                     f"seed) d_AQM {floors[-1]['d_aqm']:.2f} %, FLIP {floors[-1]['flip']:.4f}, rel RMS "
                     f"{floors[-1]['rel_rms']:.4f}")
                strip = [(np.clip(shown(ref, adaptation), 0, 1) * 255.0 + 0.5).astype(np.uint8)]
                for scale, size, mesh, img in zip(scales[1:], sizes[1:], meshes[1:], images[1:-1]):
                    rows.append(dict(frame=frame, scale=scale, element_size=size, elements=mesh.n_elements,
                                     **measure(img)))
                    strip.append(difference_picture(img, ref))
                    echo(f"  element size {size:g} (x{scale:g}, {mesh.n_elements:,} elements): d_AQM "
                         f"{rows[-1]['d_aqm']:.2f} %, FLIP {rows[-1]['flip']:.4f}, rel RMS {rows[-1]['rel_rms']:.4f}")
                pictures.append(np.concatenate(strip, axis=1))
    converged = all(f["d_aqm"] <= thr for f in floors)  # else the rows measure the photons' noise, not the mesh
    chosen = coarsest_invisible_scale(rows, thr) if converged else None
    result = dict(scene=Path(path).stem, frames=list(frames), photons=photons, width=width, height=height,
                  spp=settings.spp, d_thr_percent=thr, finest=dict(scale=scales[0], element_size=sizes[0],
                                                                   elements=meshes[0].n_elements),
                  floor=floors, rows=rows, converged=converged, coarsest_invisible_scale=chosen,
                  wall_s=time.perf_counter() - t_start)
    out_dir.mkdir(parents=True, exist_ok=True)  # only now: a refused or killed run leaves nothing
    (out_dir / "elements.json").write_text(json.dumps(result, indent=1))
    write_png(out_dir / "elements.png", np.concatenate(pictures, axis=0))
    if not converged:
        echo(f"the floor is over d_thr on some frame: the finest maps are not converged, so the rows show their "
             f"noise as much as the mesh; give more --photons (now {photons:,})")
    else:
        echo("coarsest element size whose frames are within d_thr of the finest on every frame: "
             + (f"x{chosen:g} of the scene's" if chosen is not None else f"none coarser than x{scales[0]:g}"))
    echo(f"wrote {out_dir / 'elements.json'}, {out_dir / 'elements.png'}")
    return result
