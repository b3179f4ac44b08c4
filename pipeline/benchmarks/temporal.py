"""``loom bench temporal``: temporal windows, gather and filter on PoCL for an ATRIUM-size case.

The case of §6 for ATRIUM: the real ATRIUM element mesh at the paper's size (about 43,000 elements), 300 frames,
20,000 photons per frame, F_max = 44. Photon tracing time per frame is measured by shooting a few
real ATRIUM frames at 20,000 photons (synchronous, one process); their per-element counts give the
hit rates of a synthetic 300-frame photon set (Poisson counts per element and frame, a moving
bright spot over 5 % of the elements so that windows vary; random barycentrics and energies), which
the gather then processes exactly as pipeline/collection/maps.py does: chunks of 96 output frames, element
sums of each frame once (kernels/gather.py element_sums_cl), then a prefix table over the chunk's
frames on the device, window sums and vertices (frame_sums_flux_cl), then the adaptive filter.

Reported per frame: windows, element sums (records -> per-element sums), window and vertex flux,
filter, their total against the tracing time; gather throughput in records per second; and the
NumPy twins' times on a few frames. ``--frames`` gathers fewer synthetic frames for a quick check.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING

import click
import numpy as np

from kernels.filter import adaptive_filter_cl, adaptive_filter_reference, neighbourhood
from kernels.gather import (
    element_sums_cl,
    element_sums_reference,
    frame_sums_flux_cl,
    irradiance,
    window_flux_reference,
)
from kernels.temporal import windows_cl, windows_reference
from pipeline.config import FilterConfig, PhotonConfig
from pipeline.run.shoot import plan, shoot
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import atrium, write_builtin
from pipeline.store import PhotonStore

if TYPE_CHECKING:
    from collections.abc import Callable

N_FRAMES = 300
N_PHOTONS = 20_000
FMAX = 44
CHUNK = 96  # output frames per gather call, as pipeline/collection/maps.py


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def _trace_frames(root: Path, frames: str):
    """Shoot real ATRIUM frames on the paper's mesh (about 43,000 elements, Table 2's workload, not
    the scene's own coarser one); (scene, mesh, store, seconds per traced frame)."""
    scene = read_scene(write_builtin("atrium", root / "atrium.glb"))
    config = PhotonConfig(element_size=atrium.PAPER_ELEMENT_SIZE)
    summary = shoot(plan(scene, frames, N_PHOTONS, config), str(root / "p.zarr"), scheduler="synchronous",
                    progress=False)
    return scene, ElementMesh.build(scene, config.element_size), PhotonStore.open(str(root / "p.zarr")), \
        summary["seconds"] / summary["traced_frames"], summary


class SyntheticPhotons:
    """Records of frame g drawn from per-element rates (deterministic per frame)."""

    def __init__(self, rate: np.ndarray, centres: np.ndarray, n_frames: int, seed: int = 0):
        self.rate, self.n_frames, self.seed = rate, n_frames, seed
        rng = np.random.default_rng(seed)
        self.spot = rng.choice(len(rate), max(1, len(rate) // 20), replace=False)
        self.centres = centres

    def counts(self, g: int) -> np.ndarray:
        rng = np.random.default_rng((self.seed, g))
        lam = self.rate.copy()
        phase = np.sin(2 * np.pi * (g / 60.0 + self.centres[self.spot, 0] / 10.0))
        lam[self.spot] *= 1.0 + 4.0 * np.maximum(phase, 0.0) ** 4  # a bright spot passing by
        return rng.poisson(lam).astype(np.uint32)

    def records(self, g: int) -> SimpleNamespace:
        counts = self.counts(g)
        rng = np.random.default_rng((self.seed, g, 1))
        element = np.repeat(np.arange(len(counts), dtype=np.uint32), counts)
        n = len(element)
        key = element | (np.arange(n, dtype=np.uint32) & 1) << np.uint32(30) \
            | (rng.random(n) < 0.3).astype(np.uint32) << np.uint32(31)
        b1 = rng.integers(0, 32768, n).astype(np.uint16)
        b2 = (rng.random(n) * (65535 - b1)).astype(np.uint16)
        offsets = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
        return SimpleNamespace(key=key, b1=b1, b2=b2, energy=rng.random((n, 3)).astype(np.float32),
                               offsets=offsets)


def _gather_chunk(cache: dict, photons: "SyntheticPhotons", lo: int, hi: int, n_emitted, back, fwd, rows, mesh,
                  t: dict, *, shape: dict, kind: str = "indirect"):
    """The gather as pipeline/collection/maps.py runs it for one chunk: each frame's element sums once
    (kept in ``cache`` while later chunks' windows reach the frame), then window and vertex flux
    from them on the device. Adds seconds to ``t["sums"]`` and ``t["flux"]``; returns the flux
    and the records summed."""
    n_summed = 0
    for g in range(lo, hi):
        if g not in cache:
            records = photons.records(g)
            n_summed += len(records.key)
            cache[g], dt = _timed(lambda r=records: element_sums_cl([r], kind=kind)[0])
            t["sums"] += dt
    flux, dt = _timed(lambda: frame_sums_flux_cl([cache[g] for g in range(lo, hi)], n_emitted[lo:hi], back, fwd,
                                                 rows, mesh.element_vertices, mesh.n_vertices, **shape))
    t["flux"] += dt
    return flux, n_summed


def run(trace_frames: int = 3, numpy_frames: int = 4, n_frames: int = N_FRAMES,
        echo: Callable[[str], None] = click.echo) -> dict:
    config = FilterConfig()
    with tempfile.TemporaryDirectory() as tmp:
        scene, mesh, store, trace_s, summary = _trace_frames(Path(tmp), f"150-{149 + trace_frames}")
        real = store.counts(kind="all", frames=range(149, 149 + trace_frames)).astype(np.float64)
        records_per_frame = summary["records"] / summary["traced_frames"]
    echo(f"ATRIUM: {mesh.n_elements:,} elements, {mesh.n_vertices:,} vertices; traced {trace_frames} frames "
         f"of {N_PHOTONS:,} photons: {trace_s * 1e3:.0f} ms/frame, {records_per_frame:,.0f} records/frame")

    # Synthetic frames with the real frames' per-element hit rates
    centres = mesh.vertex_local[mesh.element_vertices].mean(axis=1)
    photons = SyntheticPhotons(real.mean(axis=0) + 0.02, centres, n_frames)
    counts = np.stack([photons.counts(g) for g in range(n_frames)])
    n_emitted = np.full(n_frames, float(N_PHOTONS))
    state = scene.pose_frame(150)
    areas = mesh.vertex_areas(state)

    # Warm-up: build every program once (PoCL compile, cached on disk after the first run)
    windows_cl(counts[:8], n_emitted[:8], fmax=4)
    zero = np.zeros((1, mesh.n_elements), np.uint8)
    # The windows' shape the gather of a render takes (pipeline/collection/maps.py): the linear fit
    shape = dict(linear=True)
    wf, _ = _gather_chunk({}, photons, 0, 1, n_emitted, zero, zero, [0], mesh, dict(sums=0.0, flux=0.0),
                          shape=shape)
    hood, hood_s = _timed(neighbourhood, mesh.element_vertices, mesh.vertex_local, mesh.vertex_instance,
                          max_rings=config.filter_rings, max_angle=config.filter_angle)
    adaptive_filter_cl(wf[0], areas, hood)

    (back, fwd), t_windows = _timed(windows_cl, counts, n_emitted, fmax=FMAX)
    t = dict(sums=0.0, flux=0.0, filter=0.0)
    n_summed = 0
    filtered = 0
    cache: dict[int, np.ndarray] = {}
    for start in range(0, n_frames, CHUNK):
        out = np.arange(start, min(start + CHUNK, n_frames))
        lo = int((out[:, None] - back[out]).min())
        hi = int((out[:, None] + fwd[out]).max()) + 1
        for g in [g for g in cache if g < lo]:
            del cache[g]
        flux, n = _gather_chunk(cache, photons, lo, hi, n_emitted, back[out], fwd[out], out - lo, mesh, t,
                                shape=shape)
        n_summed += n
        (_, rings), dt = _timed(adaptive_filter_cl, flux, areas, hood, photons=config.filter_photons)
        t["filter"] += dt
        filtered += int((rings > 0).sum())
    per_frame = {k: v / n_frames * 1e3 for k, v in t.items()}
    per_frame["gather"] = per_frame["sums"] + per_frame["flux"]
    per_frame["windows"] = t_windows / n_frames * 1e3
    total = per_frame["windows"] + per_frame["gather"] + per_frame["filter"]
    result = dict(elements=mesh.n_elements, vertices=mesh.n_vertices, frames=n_frames, photons=N_PHOTONS,
                  fmax=FMAX, trace_ms=trace_s * 1e3, records_per_frame=n_summed / n_frames,
                  ms_per_frame=per_frame, total_ms=total, ratio=total / (trace_s * 1e3),
                  records_per_s=n_summed / t["sums"], records_per_s_gather=n_summed / (t["sums"] + t["flux"]),
                  mean_window=float(np.mean(back.astype(np.int64) + fwd + 1)),
                  filtered_vertices=filtered / n_frames, neighbourhood_s=hood_s)

    # Gather rate on dense frames (1,000,000 records each, up to 16 frames): the records, not the
    # elements, dominate there. Element sums alone and the whole gather (sums, then flux).
    n_dense = min(16, n_frames)
    big = SyntheticPhotons(photons.rate * (1e6 / photons.rate.sum()), centres, n_dense, seed=1)
    rows = np.arange(n_dense // 4, n_dense - n_dense // 4)
    few = np.full((len(rows), mesh.n_elements), n_dense // 4, np.uint8)
    dense = dict(sums=0.0, flux=0.0)
    _, n_big = _gather_chunk({}, big, 0, n_dense, np.full(n_dense, 1e6 / 0.75), few, few, rows, mesh, dense,
                             shape=shape, kind="all")
    result["records_per_s_sums_1M"] = n_big / dense["sums"]
    result["records_per_s_gather_1M"] = n_big / (dense["sums"] + dense["flux"])

    # NumPy twins on a few frames (per frame)
    mid = n_frames // 2
    k = max(1, min(numpy_frames, n_frames - mid))
    _, dt = _timed(windows_reference, counts, n_emitted, fmax=FMAX, frames=(mid, mid + k))
    twins = {"windows": dt / k * 1e3}
    recs = [photons.records(g) for g in range(k)]
    _, dt = _timed(element_sums_reference, recs)
    twins["sums"] = dt / k * 1e3
    lo, hi = max(0, mid - FMAX // 2), min(n_frames, mid + k + FMAX // 2)
    table = np.stack([element_sums_cl([photons.records(g)])[0] for g in range(lo, hi)])
    rows = np.arange(mid, mid + k)
    want, dt = _timed(lambda: window_flux_reference(table, n_emitted[lo:hi], back[rows], fwd[rows], rows - lo,
                                                    mesh.element_vertices, mesh.n_vertices, **shape))
    twins["flux"] = dt / k * 1e3
    flux, _ = _gather_chunk(dict(enumerate(table, lo)), photons, lo, hi, n_emitted, back[rows], fwd[rows], rows - lo,
                            mesh, dict(sums=0.0, flux=0.0), shape=shape)
    # The timed path computes what its twin does: largest difference relative to the largest value
    result["flux_twin_difference"] = float(np.abs(flux - want).max() / max(np.abs(want).max(), 1e-300))
    _, dt = _timed(lambda: [adaptive_filter_reference(flux[i], areas, hood) for i in range(len(rows))])
    twins["filter"] = dt / k * 1e3
    result["numpy_ms_per_frame"] = twins
    result["unfiltered_irradiance_max"] = float(irradiance(flux[0, 0], areas).max())

    pf = result["ms_per_frame"]
    echo(f"synthetic {n_frames} frames, {result['records_per_frame']:,.0f} records/frame, F_max = {FMAX}, "
         f"mean window {result['mean_window']:.1f} frames")
    echo(f"PoCL ms/frame: windows {pf['windows']:.2f}, gather {pf['gather']:.2f} (element sums {pf['sums']:.2f}, "
         f"window and vertex flux {pf['flux']:.2f}), filter {pf['filter']:.2f} "
         f"({result['filtered_vertices']:,.0f} vertices filtered/frame; rings built once in {hood_s:.2f} s)")
    echo(f"temporal processing {total:.2f} ms/frame = {100 * result['ratio']:.2f} % of photon tracing "
         f"({result['trace_ms']:.0f} ms/frame; target <= 5 %)")
    echo(f"records gathered: at {result['records_per_frame']:,.0f} records/frame (per-element work "
         f"dominates) {result['records_per_s_gather'] / 1e6:.1f} M/s through the whole gather; at 1,000,000 "
         f"records/frame {result['records_per_s_sums_1M'] / 1e6:.0f} M/s in the element sums, "
         f"{result['records_per_s_gather_1M'] / 1e6:.0f} M/s through the whole gather (target >= 100 M/s)")
    echo("NumPy twins ms/frame: " + ", ".join(f"{k} {v:.1f}" for k, v in twins.items()))
    return result
