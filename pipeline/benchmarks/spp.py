"""``loom bench spp``: camera samples per pixel against a converged reference, the indirect map held fixed.

For each frame K of the built-in ROOM (default 68 and 23), frames K - F_max/2 ... K + F_max/2 are shot with
a large N_frame (default 160,000 photons, F_max = 30) and K's indirect map is gathered once with adaptive
temporal collection (§5.1). The compositor (pipeline/frames/camera_paths.py) then renders K with that same map at
1, 2, 4, 8, 16 jittered camera samples a pixel and at a converged 256, so that only the pixel sampling
differs. Each image is compared with the 256-spp reference as the viewer sees it:

* FLIP mean of the shown frames (pipeline/benchmarks/error_measures.py): the default look (pipeline/frames/tonemap.py,
  filmic) at the frame's adaptation luminance, sRGB-encoded, at the pixels per degree of the AQM's
  viewing conditions (pipeline/frames/perceived.py viewing_for);
* d_AQM, the share of AQM pixels above 1 JND (pipeline/frames/perceived.py displayed_difference, Ward's
  visibility-matching display values): the measure the guided coordinator accepts photon noise by
  (d_AQM <= d_thr, §5.2.3);
* relative RMS of luminance, and the compositing time of the frame (CPU seconds of this process and wall).

The reference's own sampling error is stated by a second 256-spp rendering with another seed
(``--seed-check``): its FLIP and d_AQM against the reference are the floor of the table.

A two-pass prototype of adaptive sampling is measured beside them at equal mean samples a pixel B
(``--adaptive``, default 4 and 8): a first pass of B/2 samples a pixel, then 3B/2 more samples in the third
of the pixels whose displayed value is most uncertain (:func:`displayed_spread`: the standard error of the
samples' shown luma, largest in a 3x3 neighbourhood, so a clipped highlight needs nothing and a speckled rim
or a stair-stepped silhouette does; :func:`allot_extra`). It is built from whole-frame renders with other
seeds (the first pass as B/2 one-sample frames, the second as one frame of 3B/2 samples kept in the chosen
pixels), so its CPU time is the first pass plus the chosen share of the second: what a compositor that
traced only those pixels would spend, at the measured cost of a sample.

Decision (:func:`smallest_invisible_spp`): the smallest spp from which every larger measured spp has
d_AQM against the reference at most d_thr on every frame, i.e. the pixels' sampling error is no more
visible than the photon noise the guided default accepts.
"""
from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps
from pipeline.config import RenderConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame, visible_adaptation
from pipeline.frames.perceived import displayed_difference
from pipeline.frames.settings import RenderSettings
from pipeline.photons.raycast import caster_for
from pipeline.run.shoot import plan, shoot
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore

from .error_measures import LUMA, flip_mean, frame_ppd, relative_rms, shown

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

FRAMES = (68, 23)  # ROOM's segment centre K2 (§6, Table 1), and a frame of the first segment
SPPS = (1, 2, 4, 8, 16)
REFERENCE_SPP = 256
ADAPTIVE_BUDGETS = (4, 8)  # mean samples a pixel of the two-pass prototype, compared with uniform spp
ADAPTIVE_SHARE = 1.0 / 3.0  # share of pixels the second pass samples (fixed a priori, not fitted)


def smallest_invisible_spp(rows: Sequence[dict], threshold: float, key: str = "d_aqm") -> int | None:
    """The smallest ``spp`` of ``rows`` (dicts with "spp", "frame" and ``key``) from which every row of
    that or a larger spp, on every frame, has ``key`` <= ``threshold``; None if even the largest fails."""
    spps = sorted({int(r["spp"]) for r in rows})
    worst = {s: max(float(r[key]) for r in rows if int(r["spp"]) == s) for s in spps}
    best = None
    for s in reversed(spps):
        if worst[s] > threshold:
            break
        best = s
    return best


def allot_extra(spread: np.ndarray, share: float) -> np.ndarray:
    """Boolean mask of the ``share`` of pixels with the largest ``spread`` (ties: the earlier pixel in
    row-major order first), the pixels a second pass gives more samples: deterministic for a given image."""
    flat = np.asarray(spread, np.float64).ravel()
    n = int(round(share * flat.size))
    order = np.argsort(-flat, kind="stable")
    mask = np.zeros(flat.size, bool)
    mask[order[:n]] = True
    return mask.reshape(np.shape(spread))


def displayed_spread(samples: Sequence[np.ndarray], adaptation: float) -> np.ndarray:
    """Per pixel, the largest standard error of a displayed value in its 3x3 neighbourhood, from the
    first-pass samples (N, H, W, 3): the standard deviation of the samples' shown luma (:func:`shown`,
    Rec. 709 weights) over sqrt(N). The neighbourhood catches an edge pixel whose few samples happened to
    agree (4 samples of a half-covered pixel agree one time in 8), as Mitchell's refinement test looks at
    a region's contrast, not one sample's (D. P. Mitchell, "Generating antialiased images at low sampling
    densities", SIGGRAPH 1987)."""
    y = np.stack([shown(s, adaptation) @ LUMA for s in samples])
    err = y.std(axis=0, ddof=1) / np.sqrt(len(samples))
    padded = np.pad(err, 1, mode="edge")
    h, w = err.shape
    return np.max([padded[i:i + h, j:j + w] for i in range(3) for j in range(3)], axis=0)


def adaptive_image(first: Sequence[np.ndarray], extra: np.ndarray, extra_spp: int, mask: np.ndarray) -> np.ndarray:
    """Pixel means of a two-pass image: the first pass's N samples (N, H, W, 3) everywhere, and in ``mask``
    also ``extra_spp`` more samples whose mean is ``extra`` (H, W, 3), each sample weighted alike."""
    n = len(first)
    total = np.sum(first, axis=0)
    both = (total + extra_spp * extra) / (n + extra_spp)
    return np.where(mask[..., None], both, total / n)


def run(frames: Iterable[int] = FRAMES, *, spps: Sequence[int] = SPPS, reference_spp: int = REFERENCE_SPP,
        photons: int = 160_000, fmax: int = 30, width: int = 320, height: int = 240, seed_check: bool = True,
        adaptive: Sequence[int] = ADAPTIVE_BUDGETS,
        store: str | None = None, json_path: str | None = None,
        echo: Callable[[str], None] = click.echo) -> dict:
    settings = RenderSettings(width=width, height=height)
    config = RenderConfig()
    thr = 100.0 * config.segments.d_thr
    ppd = frame_ppd(width, height)
    tmp = tempfile.TemporaryDirectory(prefix="bench-spp-") if store is None else None
    root = Path(tmp.name if tmp else store)
    root.mkdir(parents=True, exist_ok=True)
    rows, floors, arows = [], [], []
    try:
        path = write_builtin("room", root / "room.glb")
        scene = read_scene(path)
        mesh = ElementMesh.build(scene, config.photons.element_size)
        url = str(root / "photons.zarr")
        half = fmax // 2
        echo(f"ROOM at {width}x{height}, {ppd:.1f} pixels/degree; indirect maps of {photons:,} photons a frame, "
             f"F_max = {fmax} adaptive; reference {reference_spp} spp; d_thr = {thr:g} %")
        for k in frames:
            lo, hi = max(1, k - half), min(scene.timeline.frames, k + half)
            shoot(plan(scene, f"{lo}-{hi}", photons, config.photons), url, scheduler="synchronous", progress=False)
            (lit,) = illumination_maps(PhotonStore.open(url), mesh, scene,
                                       MapRequest(WindowSpec("adaptive", fmax), [k - 1]), config.collection)
            irradiance = lit.irradiance
            state = scene.pose_frame(k)
            caster = caster_for(state)
            adaptation = visible_adaptation(state, mesh, irradiance, settings, config.photons.seed)

            def composite(spp: int, seed: int = config.photons.seed, state=state, caster=caster, irradiance=irradiance,
                          k=k):
                c0, w0 = time.process_time(), time.perf_counter()
                paths = CameraPaths(width, height, spp, seed, k, settings.reflection_depth, settings.area_samples)
                img = render_frame(state, mesh, irradiance, paths, caster=caster)
                return img.beauty, time.process_time() - c0, time.perf_counter() - w0

            ref, ref_cpu, ref_wall = composite(reference_spp)
            ref_shown = shown(ref, adaptation)

            def measure(img, cpu, wall, spp, k=k, ref=ref, ref_shown=ref_shown, adaptation=adaptation):
                return dict(frame=k, spp=spp, flip=flip_mean(shown(img, adaptation), ref_shown, ppd),
                            d_aqm=displayed_difference(img, ref, adaptation, aqm_size=config.segments.aqm_size).d_aqm,
                            rel_rms=relative_rms(img, ref),
                            cpu_s=cpu, wall_s=wall)

            for spp in spps:
                rows.append(measure(*composite(spp), spp))
                echo(_row(rows[-1]))
            for budget in adaptive:  # first pass budget/2 samples, then 3x that in the noisiest third
                n0, share = max(2, budget // 2), ADAPTIVE_SHARE
                extra_spp = int(round((budget - n0) / share))
                first, cpu = [], 0.0
                for i in range(n0):
                    img, c, _ = composite(1, seed=config.photons.seed + 1000 + i)
                    first.append(img)
                    cpu += c
                extra, c, _ = composite(extra_spp, seed=config.photons.seed + 2000)
                mask = allot_extra(displayed_spread(first, adaptation), share)
                cpu += c * float(mask.mean())  # the extra pass traced only in the chosen pixels
                row = measure(adaptive_image(first, extra, extra_spp, mask), cpu, float("nan"),
                              n0 + extra_spp * float(mask.mean()))
                row["adaptive"] = f"{n0} + {extra_spp} in {100 * share:.0f} %"
                arows.append(row)
                echo(_row(row) + f" (adaptive: {row['adaptive']})")
            if seed_check:
                other, cpu, wall = composite(reference_spp, seed=config.photons.seed + 1)
                floors.append(measure(other, cpu, wall, reference_spp))
                echo(_row(floors[-1]) + " (a second reference, another seed)")
            echo(f"frame {k}: L_wa {adaptation:.4f}; the reference took {ref_cpu:.1f} s CPU, {ref_wall:.1f} s wall")
        echo("")
        echo("| frame | spp | FLIP mean | d_AQM | rel. RMS (luminance) | composite CPU s | composite wall s |")
        echo("|---|---|---|---|---|---|---|")
        for r in rows + floors:
            echo(_row(r))
        if arows:
            echo("")
            echo("| frame | samples a pixel (mean) | two-pass | FLIP mean | d_AQM | rel. RMS | CPU s (first pass + "
                 "share of the second) | uniform spp at that mean: FLIP, d_AQM |")
            echo("|---|---|---|---|---|---|---|---|")
            uniform = {(r["frame"], r["spp"]): r for r in rows}
            for r in arows:
                u = uniform.get((r["frame"], int(round(r["spp"]))))
                same = f"{u['flip']:.4f}, {u['d_aqm']:.2f} %" if u else "-"
                echo(f"| {r['frame']} | {r['spp']:.2f} | {r['adaptive']} | {r['flip']:.4f} | {r['d_aqm']:.2f} % "
                     f"| {100 * r['rel_rms']:.2f} % | {r['cpu_s']:.2f} | {same} |")
        choice = smallest_invisible_spp(rows, thr)
        echo(f"smallest spp from which d_AQM against {reference_spp} spp is at most d_thr = {thr:g} % on every "
             f"frame: {choice if choice is not None else 'none of ' + ', '.join(map(str, spps))}")
        result = dict(rows=rows, reference_floor=floors, adaptive=arows, d_thr=thr, choice=choice, ppd=ppd,
                      photons=photons, fmax=fmax, width=width, height=height, reference_spp=reference_spp)
        if json_path:
            Path(json_path).write_text(json.dumps(result, indent=1))
        return result
    finally:
        if tmp is not None:
            tmp.cleanup()


def _row(r: dict) -> str:
    return (f"| {r['frame']} | {r['spp']} | {r['flip']:.4f} | {r['d_aqm']:.2f} % | {100 * r['rel_rms']:.2f} % "
            f"| {r['cpu_s']:.2f} | {r['wall_s']:.2f} |")
