"""``loom bench noise``: the AQM's even/odd noise test (§5.2.3) on ROOM frame 68, and what drives it.

For N_frame = 10,000 ... 80,000 photons per frame (doubled in one store, as the loop of §5.2.3 does),
frames K - F_max/2 ... K + F_max/2 of the built-in ROOM are shot, the indirect map of K is gathered
from the even and the odd photons with adaptive temporal collection (Condition (1), §5.1), and the
two halves are composited with the same camera samples and direct light into I1(K), I2(K)
(workers/composite.py). Reported per N_frame:

* d_AQM of I1 vs I2 (a) on linear values with 1.0 = 100 cd/m^2 (``pipeline.aqm.aqm``, what
  ``loom aqm`` of the EXRs gives), (b) on the displayed values after Ward's tone mapping at the
  frame's adaptation luminance (``pipeline.frames.perceived``), (c) displayed, with the adaptive spatial
  filter of §5.2.5 applied to both halves (``FilterConfig.filter_*``), and displayed with fixed
  +-F_max/2 windows (every photon of the segment: the least noise temporal pooling can give);
* the share of vertex maps the filter touched, the mean window length back + fwd + 1 per element,
  p_me back / fwd (share of elements hit in the segment whose window reaches F_max/2 that way), and
  sigma_v, the flux-weighted relative standard error of one half's vertex irradiance from the split
  (|E1 - E2| / sqrt(2), times 1.2533 for the mean absolute deviation);
* L_wa (mesh-based adaptation luminance of K: its own direct photons plus the indirect map shown)
  and Ward's scale m, i.e. how bright the frame is displayed.

Then, once, the AQM's own sensitivity on this frame (``--calibrate``): the amplitude of independent
per-vertex multiplicative Gaussian noise on the largest N_frame's full indirect map that gives
d_AQM = d_thr (3 %), and d_AQM of a uniform +10 % step of the whole frame. Comparing sigma_v with
that amplitude says how many photons the test needs.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from kernels import colour
from pipeline.aqm import aqm
from pipeline.collection.estimators import mesh_adaptation, vertex_irradiance
from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps, window_counts
from pipeline.config import PhotonConfig, RenderConfig
from pipeline.errors import LoomError
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.frames.perceived import displayed_difference
from pipeline.frames.tonemap import ToneMapping, ward_scale
from pipeline.photons.raycast import caster_for
from pipeline.run.shoot import plan, shoot
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

LUMA = np.asarray(colour.LUMA)  # Rec. 709 (kernels/colour.py)
K = 68  # ROOM's segment centre K2 (§6, Table 1)


def split_noise(irradiance: np.ndarray, areas: np.ndarray) -> float:
    """Flux-weighted relative standard error of one half's vertex irradiance from the two halves
    (2, V, 3): sum A E r / sum A E with r = 1.2533 |E1 - E2| / (sqrt(2) E) (docs/05-estimators.md §1.4)."""
    y = irradiance @ LUMA
    mean = y.mean(axis=0)
    ok = mean > 0
    sigma = 1.2533 * np.abs(y[0] - y[1]) / np.sqrt(2.0)
    return float(np.sum(areas[ok] * sigma[ok]) / np.sum(areas[ok] * mean[ok]))


def noise_for_threshold(base: np.ndarray, noise_images: Sequence[np.ndarray], adaptation: float, target: float, *,
                        aqm_size: int, hi: float = 0.2, steps: int = 14) -> float:
    """Amplitude s of per-vertex noise with displayed d_AQM(base + s n1, base + s n2) = target (%).

    ``noise_images`` are the indirect layers rendered with the map E_ref x g (g ~ N(0, 1) per
    vertex, one draw per image): the compositor is linear in the map, so E_ref (1 + s g) renders
    to base + s x layer. Bisection; d_AQM grows with s."""
    def d(s: float) -> float:
        a, b = (np.maximum(base + s * n, 0.0) for n in noise_images)
        return displayed_difference(a, b, adaptation, aqm_size=aqm_size).d_aqm

    lo = 0.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if d(mid) < target else (lo, mid)
    return 0.5 * (lo + hi)


def run(photons: Iterable[int] = (10_000, 20_000, 40_000, 80_000), *, fmax: int = 30, width: int = 320,
        height: int = 240, spp: int = 2, element_scale: float = 1.0, filter_photons: float | None = None,
        calibrate: bool = True, scheduler: str = "synchronous", workers: int | None = None, store: str | None = None,
        echo: Callable[[str], None] = click.echo) -> dict:
    tmp = tempfile.TemporaryDirectory(prefix="bench-noise-") if store is None else None
    root = Path(tmp.name if tmp else store)
    root.mkdir(parents=True, exist_ok=True)
    try:
        path = write_builtin("room", root / "room.glb")
        scene = read_scene(path)
        own = ElementMesh.build(scene).element_size
        config = RenderConfig(photons=PhotonConfig(element_size=own * element_scale))
        if filter_photons is not None:
            config = config.replace(filter=config.filter.replace(filter_photons=filter_photons))
        mesh = ElementMesh.build(scene, config.photons.element_size)
        state = scene.pose_frame(K)
        caster = caster_for(state)
        paths = CameraPaths(width, height, spp, config.photons.seed, K)
        areas = mesh.vertex_areas(state)
        index = K - 1
        half = fmax // 2
        url = str(root / f"photons-es{config.photons.element_size:g}.zarr")
        thr = 100.0 * config.segments.d_thr
        echo(f"ROOM frame {K}: {mesh.n_elements:,} elements (element_size {config.photons.element_size:g} m), "
             f"{mesh.n_vertices:,} vertices; frames {K - half}-{K + half}, F_max = {fmax} adaptive; "
             f"{width}x{height}, {spp} spp; filter_photons {config.filter.filter_photons:g}, "
             f"filter_rings {config.filter.filter_rings}")

        def pair(irradiance):  # I1(K), I2(K): same camera samples and direct light
            return [render_frame(state, mesh, irradiance[p], paths, caster=caster) for p in (0, 1)]

        def maps(pstore, mode, filter=None):
            return next(illumination_maps(pstore, mesh, scene, MapRequest(WindowSpec(mode, fmax), [index], halves=True),
                                          config.collection, filter))

        rows = []
        last = None
        for n in sorted(photons):
            t0 = time.perf_counter()
            # the records kept: the direct estimate below is made from them
            shoot(plan(scene, f"{K - half}-{K + half}", int(n), config.photons), url, keep_records=True,
                  scheduler=scheduler, workers=workers, progress=False)
            pstore = PhotonStore.open(url)
            if pstore.photons_emitted(index) != n:
                raise LoomError(f"holds {pstore.photons_emitted(index):,} photons for frame {K}, more than "
                                f"N_frame = {n:,}; use a new --store or larger --photons", path=url, field="--store")
            rec = pstore.read_frame(index)
            d = rec.direct
            direct = vertex_irradiance(rec.element[d], rec.b1[d], rec.b2[d], rec.energy[d], mesh, areas,
                                       rec.photons_emitted)
            lit = maps(pstore, "adaptive")
            filt = maps(pstore, "adaptive", config.filter)
            fixed = maps(pstore, "fixed")
            shown = lit.irradiance.mean(axis=0)  # the full map: both halves pooled
            adaptation = mesh_adaptation(state, mesh, direct + shown, width / height)
            images = {name: pair(m.irradiance) for name, m in (("adaptive", lit), ("filter", filt), ("fixed", fixed))}

            def disp(name, images=images, adaptation=adaptation):
                a, b = images[name]
                return displayed_difference(a.beauty, b.beauty, adaptation, aqm_size=config.segments.aqm_size).d_aqm

            a, b = images["adaptive"]
            counts = window_counts(pstore, frames=range(index - half, index + half + 1))
            hit = np.asarray(counts).sum(axis=0) > 0
            back, fwd = lit.back.astype(np.int64), lit.fwd.astype(np.int64)
            row = dict(n_frame=int(n), d_linear=aqm(a.beauty, b.beauty, aqm_size=config.segments.aqm_size).d_aqm,
                       d_displayed=disp("adaptive"), d_filtered=disp("filter"), d_fixed=disp("fixed"),
                       filtered=float(np.mean(filt.rings > 0)), mean_window=float(np.mean(back + fwd + 1)),
                       p_me_back=float(np.mean(back[hit] == half)), p_me_fwd=float(np.mean(fwd[hit] == half)),
                       sigma_v=split_noise(lit.irradiance, areas), adaptation=adaptation,
                       ward_m=ward_scale(adaptation * ToneMapping().nits_per_unit), seconds=time.perf_counter() - t0)
            rows.append(row)
            last = (shown, direct, adaptation, a)
        echo("")
        echo("| N_frame | d_AQM linear x100 | d_AQM displayed | displayed + filter | displayed, fixed windows "
             "| vertices filtered | mean window | p_me back / fwd | sigma_v (one half) | L_wa | m |")
        echo("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            echo(f"| {r['n_frame']:,} | {r['d_linear']:.1f} % | {r['d_displayed']:.1f} % | {r['d_filtered']:.1f} % "
                 f"| {r['d_fixed']:.1f} % | {100 * r['filtered']:.0f} % | {r['mean_window']:.1f} "
                 f"| {100 * r['p_me_back']:.0f} / {100 * r['p_me_fwd']:.0f} % | {100 * r['sigma_v']:.1f} % "
                 f"| {r['adaptation']:.4f} | {r['ward_m']:.1f} |")
        echo(f"(d_thr = {thr:g} %; {sum(r['seconds'] for r in rows):.0f} s for the rows)")
        result = dict(rows=rows, elements=mesh.n_elements, element_size=config.photons.element_size)

        if calibrate and last is not None:
            shown, direct, adaptation, a = last
            base = render_frame(state, mesh, shown, paths, caster=caster).beauty
            rng = np.random.default_rng(1)
            layers = [render_frame(state, mesh, shown * rng.standard_normal(mesh.n_vertices)[:, None], paths,
                                   caster=caster).indirect
                      for _ in range(2)]
            amp = noise_for_threshold(base, layers, adaptation, thr, aqm_size=config.segments.aqm_size)
            step = displayed_difference(base, base * 1.10, adaptation, aqm_size=config.segments.aqm_size).d_aqm
            result.update(noise_at_threshold=amp, uniform_step_10=step)
            n_max = rows[-1]["n_frame"]
            need = n_max * (rows[-1]["sigma_v"] / amp) ** 2
            echo(f"AQM sensitivity on this frame (displayed): per-vertex multiplicative noise of {100 * amp:.2f} % "
                 f"rms in each image gives d_AQM = {thr:g} %; a uniform +10 % step of the whole frame gives "
                 f"{step:.1f} %. sigma_v at {n_max:,} is {100 * rows[-1]['sigma_v']:.1f} %: at least "
                 f"{need:,.0f} photons per frame to reach it unfiltered (sigma_v ~ N^-1/2; it falls slower "
                 f"where windows shrink).")
        return result
    finally:
        if tmp is not None:
            tmp.cleanup()
