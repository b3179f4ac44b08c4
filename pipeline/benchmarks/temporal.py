"""``loom bench temporal``: temporal windows, gather and filter on PoCL for an ATRIUM-size case.

The case of §6 for ATRIUM: the real ATRIUM element mesh (about 43,000 elements), 300 frames,
20,000 photons per frame, F_max = 44. Photon tracing time per frame is measured by shooting a few
real ATRIUM frames at 20,000 photons (synchronous, one process); their per-element counts give the
hit rates of a synthetic 300-frame photon set (Poisson counts per element and frame, a moving
bright spot over 5 % of the elements so that windows vary; random barycentrics and energies), which
the gather then processes exactly as pipeline/temporal.py does: chunks of 32 output frames, element
sums into a prefix table on the device, window sums, vertices, then the adaptive filter.

Reported per frame: windows, element sums (records -> per-element sums), window flux (prefix and,
for the decision, direct), filter, their total against the tracing time; gather throughput in
records per second; and the NumPy twins' times on a few frames.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import click
import numpy as np

N_FRAMES = 300
N_PHOTONS = 20_000
FMAX = 44
CHUNK = 96  # output frames per gather call, as pipeline/temporal.py


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def _trace_frames(root: Path, frames: str):
    """Shoot real ATRIUM frames; (scene, mesh, store, seconds per traced frame)."""
    from pipeline.config import RenderConfig
    from pipeline.scene import ElementMesh, Scene
    from pipeline.scene.builtin import write_builtin
    from pipeline.shoot import shoot
    from pipeline.store import PhotonStore

    path = write_builtin("atrium", root / "atrium.glb")
    summary = shoot(str(path), frames=frames, n_photons=N_PHOTONS, store_url=str(root / "p.zarr"),
                    config=RenderConfig(), scheduler="synchronous", progress=False)
    scene = Scene.load(path)
    return scene, ElementMesh.build(scene), PhotonStore.open(str(root / "p.zarr")), \
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

    def records(self, g: int):
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


def _sums_prefix_seconds(frames, n_elements: int, repeat: int = 3) -> float:
    """Best time of the gather's record kernel alone (sums_prefix_step, one launch a frame, the
    buffers over the records made beforehand)."""
    from kernels.context import device_context, kernel, scratch
    from kernels.gather import _in_place

    ctx, queue = device_context()
    bufs = [[_in_place(ctx, np.asarray(a, dt)) for a, dt in (
        (r.key, np.uint32), (r.b1, np.uint16), (r.b2, np.uint16), (r.energy, np.float32),
        (r.offsets, np.int64))] for r in frames]
    table = scratch("gather.table", 8 * (len(frames) + 1) * n_elements * 12)
    step = kernel("gather", "sums_prefix_step")
    best = float("inf")
    for _ in range(repeat):
        queue.finish()
        t0 = time.perf_counter()
        for j, args in enumerate(bufs):
            step(queue, (n_elements,), None, *args, np.int32(j), np.int32(len(frames)),
                 np.int32(n_elements), np.uint32(3), np.int32(1), table)
        queue.finish()
        best = min(best, time.perf_counter() - t0)
    return best

def _window_kernels(sums, n_emitted, back, fwd, rows, mesh, repeat: int = 3) -> tuple[float, float]:
    """Best times of the vertex_window_flux kernel on device tables: prefix sums, direct sums."""
    from kernels.context import device_context
    from kernels.gather import _flux, _upload

    ctx, queue = device_context()
    n_rows, n_elements, n_parity = sums.shape[:3]
    per_frame = np.ascontiguousarray(sums.reshape(n_rows, n_elements, -1).transpose(1, 0, 2))
    prefix = np.zeros((n_elements, n_rows + 1, per_frame.shape[2]))
    np.cumsum(per_frame, axis=1, out=prefix[:, 1:])
    times = []
    for table, is_prefix in ((prefix, True), (per_frame, False)):
        d_table = _upload(ctx, table)
        best = float("inf")
        for _ in range(repeat):
            queue.finish()
            t0 = time.perf_counter()
            _flux(d_table, is_prefix, n_emitted, back, fwd, rows, mesh.element_vertices, mesh.n_vertices,
                  n_elements, n_parity)
            best = min(best, time.perf_counter() - t0)
        times.append(best)
        del d_table
    return times[0], times[1]


def run(trace_frames: int = 3, numpy_frames: int = 4, echo=click.echo) -> dict:
    from kernels.filter import adaptive_filter_cl, adaptive_filter_reference, neighbourhood
    from kernels.gather import (
        element_sums_cl,
        element_sums_reference,
        gather_flux_cl,
        irradiance,
        window_flux_cl,
        window_flux_reference,
    )
    from kernels.temporal import windows_cl, windows_reference
    from pipeline.config import RenderConfig

    config = RenderConfig()
    with tempfile.TemporaryDirectory() as tmp:
        scene, mesh, store, trace_s, summary = _trace_frames(Path(tmp), f"150-{149 + trace_frames}")
        real = store.counts(kind="all", frames=range(149, 149 + trace_frames)).astype(np.float64)
        records_per_frame = summary["records"] / summary["traced_frames"]
    echo(f"ATRIUM: {mesh.n_elements:,} elements, {mesh.n_vertices:,} vertices; traced {trace_frames} frames "
         f"of {N_PHOTONS:,} photons: {trace_s * 1e3:.0f} ms/frame, {records_per_frame:,.0f} records/frame")

    # Synthetic 300 frames with the real frames' per-element hit rates
    centres = mesh.vertex_local[mesh.element_vertices].mean(axis=1)
    photons = SyntheticPhotons(real.mean(axis=0) + 0.02, centres, N_FRAMES)
    counts = np.stack([photons.counts(g) for g in range(N_FRAMES)])
    n_emitted = np.full(N_FRAMES, float(N_PHOTONS))
    state = scene.pose_frame(150)
    areas = mesh.vertex_areas(state)

    # Warm-up: build every program once (PoCL compile, cached on disk after the first run)
    windows_cl(counts[:8], n_emitted[:8], fmax=4)
    warm = element_sums_cl([photons.records(0)])
    zero = np.zeros((1, mesh.n_elements), np.uint8)
    wf = window_flux_cl(warm, n_emitted[:1], zero, zero, [0], mesh.element_vertices, mesh.n_vertices)
    hood, hood_s = _timed(neighbourhood, mesh.element_vertices, mesh.vertex_local, mesh.vertex_instance,
                          max_rings=config.filter_rings, max_angle=config.filter_angle)
    adaptive_filter_cl(wf[0], areas, hood)

    (back, fwd), t_windows = _timed(windows_cl, counts, n_emitted, fmax=FMAX)
    t = dict(gather=0.0, sums=0.0, flux_prefix=0.0, flux_direct=0.0, filter=0.0)
    n_records = 0
    n_summed = 0
    filtered = 0
    cache: dict[int, object] = {}
    for start in range(0, N_FRAMES, CHUNK):
        out = np.arange(start, min(start + CHUNK, N_FRAMES))
        lo = int((out[:, None] - back[out]).min())
        hi = int((out[:, None] + fwd[out]).max()) + 1
        for g in [g for g in cache if g < lo]:
            del cache[g]
        for g in range(lo, hi):
            if g not in cache:
                cache[g] = photons.records(g)
                n_records += len(cache[g].key)
        recs = [cache[g] for g in range(lo, hi)]
        n_summed += sum(len(r.key) for r in recs)
        # What pipeline/temporal.py runs: records -> prefix table -> windows -> vertices, on device
        flux, dt = _timed(gather_flux_cl, recs, n_emitted[lo:hi], back[out], fwd[out], out - lo,
                          mesh.element_vertices, mesh.n_vertices)
        t["gather"] += dt
        # The same in steps through host memory, to time each and compare prefix with direct sums
        sums, dt = _timed(element_sums_cl, recs)
        t["sums"] += dt
        for method in ("prefix", "direct"):
            _, dt = _timed(window_flux_cl, sums, n_emitted[lo:hi], back[out], fwd[out], out - lo,
                           mesh.element_vertices, mesh.n_vertices, method=method)
            t["flux_" + method] += dt
        if lo <= N_FRAMES // 2 < hi:  # one chunk: prefix vs direct window sums, device tables only
            t["kernel_prefix"], t["kernel_direct"] = _window_kernels(sums, n_emitted[lo:hi], back[out], fwd[out],
                                                                     out - lo, mesh)
            t["kernel_frames"] = len(out)
        del sums
        (_, rings), dt = _timed(adaptive_filter_cl, flux, areas, hood, photons=config.filter_photons)
        t["filter"] += dt
        filtered += int((rings > 0).sum())
    kernel_frames = t.pop("kernel_frames")
    kernels_ms = {k: t.pop(k) / kernel_frames * 1e3 for k in ("kernel_prefix", "kernel_direct")}
    per_frame = {k: v / N_FRAMES * 1e3 for k, v in t.items()}
    per_frame.update(kernels_ms)
    per_frame["windows"] = t_windows / N_FRAMES * 1e3
    total = per_frame["windows"] + per_frame["gather"] + per_frame["filter"]
    result = dict(elements=mesh.n_elements, vertices=mesh.n_vertices, frames=N_FRAMES, photons=N_PHOTONS,
                  fmax=FMAX, trace_ms=trace_s * 1e3, records_per_frame=n_records / N_FRAMES,
                  ms_per_frame=per_frame, total_ms=total, ratio=total / (trace_s * 1e3),
                  records_per_s=n_summed / t["sums"], records_per_s_gather=n_summed / t["gather"],
                  mean_window=float(np.mean(back.astype(np.int64) + fwd + 1)),
                  filtered_vertices=filtered / N_FRAMES, neighbourhood_s=hood_s)

    # Gather rate on dense frames (1,000,000 records each, 16 frames): the records, not the
    # elements, dominate there. Kernel alone (records -> prefix table) and the whole gather.
    big = SyntheticPhotons(photons.rate * (1e6 / photons.rate.sum()), centres, 16, seed=1)
    recs = [big.records(g) for g in range(16)]
    n_big = sum(len(r.key) for r in recs)
    result["records_per_s_kernel_1M"] = n_big / _sums_prefix_seconds(recs, mesh.n_elements)
    rows = np.arange(4, 12)
    few = np.full((len(rows), mesh.n_elements), 4, np.uint8)
    _, dt = _timed(gather_flux_cl, recs, np.full(16, 1e6 / 0.75), few, few, rows, mesh.element_vertices,
                   mesh.n_vertices, kind="all")
    result["records_per_s_gather_1M"] = n_big / dt

    # NumPy twins on a few frames (per frame)
    k = numpy_frames
    mid = N_FRAMES // 2
    _, dt = _timed(windows_reference, counts, n_emitted, fmax=FMAX, frames=(mid, mid + k))
    twins = {"windows": dt / k * 1e3}
    recs = [photons.records(g) for g in range(k)]
    _, dt = _timed(element_sums_reference, recs)
    twins["sums"] = dt / k * 1e3
    lo, hi = mid - FMAX // 2, mid + k + FMAX // 2
    table = np.stack([element_sums_cl([photons.records(g)])[0] for g in range(lo, hi)])
    rows = np.arange(mid, mid + k)
    _, dt = _timed(window_flux_reference, table, n_emitted[lo:hi], back[rows], fwd[rows], rows - lo,
                   mesh.element_vertices, mesh.n_vertices)
    twins["flux"] = dt / k * 1e3
    flux = window_flux_cl(table, n_emitted[lo:hi], back[rows], fwd[rows], rows - lo,
                          mesh.element_vertices, mesh.n_vertices)
    _, dt = _timed(lambda: [adaptive_filter_reference(flux[i], areas, hood) for i in range(k)])
    twins["filter"] = dt / k * 1e3
    result["numpy_ms_per_frame"] = twins
    result["unfiltered_irradiance_max"] = float(irradiance(flux[0, 0], areas).max())

    pf = result["ms_per_frame"]
    echo(f"synthetic {N_FRAMES} frames, {result['records_per_frame']:,.0f} records/frame, F_max = {FMAX}, "
         f"mean window {result['mean_window']:.1f} frames")
    echo(f"PoCL ms/frame: windows {pf['windows']:.2f}, gather {pf['gather']:.2f}, filter {pf['filter']:.2f} "
         f"({result['filtered_vertices']:,.0f} vertices filtered/frame; rings built once in {hood_s:.2f} s)")
    echo(f"  window sums on the device (vertex_window_flux alone, one chunk): prefix sums "
         f"{pf['kernel_prefix']:.2f}, direct sums over the window {pf['kernel_direct']:.2f}")
    echo(f"  gather in steps through host memory instead: element sums {pf['sums']:.2f}, window flux by "
         f"prefix sums {pf['flux_prefix']:.2f}, by direct window sums {pf['flux_direct']:.2f}")
    echo(f"temporal processing {total:.2f} ms/frame = {100 * result['ratio']:.2f} % of photon tracing "
         f"({result['trace_ms']:.0f} ms/frame; target <= 5 %)")
    echo(f"records gathered: at {result['records_per_frame']:,.0f} records/frame (per-element work "
         f"dominates) {result['records_per_s_gather'] / 1e6:.1f} M/s through the whole gather; at 1,000,000 "
         f"records/frame {result['records_per_s_kernel_1M'] / 1e6:.0f} M/s in the gather kernel, "
         f"{result['records_per_s_gather_1M'] / 1e6:.0f} M/s through the whole gather (target >= 100 M/s)")
    echo("NumPy twins ms/frame: " + ", ".join(f"{k} {v:.1f}" for k, v in twins.items()))
    return result
