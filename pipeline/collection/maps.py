"""Spatiotemporal illumination maps from a photon store (§5.1, §5.2.4, §5.2.5).

What the render pipeline calls to turn stored photons into per-frame vertex irradiance:

1. windows   from the store's frames x elements count table (never the records), per frame and
             element, Condition (1) (kernels/temporal.py), as a WindowSpec says: adaptive | fixed |
             off, up to F_max;
2. gather    per chunk of output frames the element sums of every frame its windows reach
             (stored with the photons, read once per frame and worker: pipeline/collection/batch_sums.py),
             turned into prefix sums over frames on the device; per output frame the window sums as
             differences of prefix sums, pooled over the photons emitted in the window,
             distributed to the vertices (kernels/gather.py);
3. filter    optionally the adaptive object-space filter for vertices that collected too few
             photons (kernels/filter.py, §5.2.5).

Windows never cross a frame without photons: each maximal run of consecutive frames that have
photons is its own animation, with its own ends. Frames sharing another frame's photons
(camera-only motion) count as frames with those photons.

Memory: output frames are processed in chunks of consecutive frames; a chunk holds the element
sums of its frames and their windows' reach (F_max/2 each side): (chunk + F_max) x E x 12 doubles
per photon parity, about 590 MB for ATRIUM on the paper's mesh (43,000 elements, F_max = 44, chunk 96). The per-batch
sums are kept (pipeline/collection/batch_sums.FrameSums, bounded by bytes), so frames in the overlap of two
chunks that run on one worker are read once.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable, Iterator

import numpy as np
import numpy.typing as npt

from kernels.filter import adaptive_filter_cl, neighbourhood
from kernels.gather import frame_sums_flux_cl, irradiance
from kernels.temporal import MAX_HALF_FMAX, MODES, windows_cl
from pipeline.collection.estimators import frame_geometry
from pipeline.config import CollectionConfig, FilterConfig
from pipeline.errors import LoomError
from pipeline.stage_clock import StageClock

from .batch_sums import FRAME_SUMS
from .regional_steps import clamp_windows, element_cuts, region_levels

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh, Scene
    from pipeline.store import PhotonStore


@dataclass(frozen=True)
class WindowSpec:
    """How far a frame's windows reach: ``mode`` "adaptive" (Condition (1), §5.1; each window's
    linear fit at the frame, docs/05-estimators.md §1.6), "fixed" (+-F_max/2 pooled, always, §6
    Fig. 3b) or "off" (the frame alone), and F_max in frames: ``--temporal`` and ``--fmax``, checked
    when made (:func:`check_window_options`)."""

    mode: str
    fmax: int

    def __post_init__(self) -> None:
        check_window_options(self.mode, self.fmax)
        object.__setattr__(self, "fmax", int(self.fmax))


@dataclass(frozen=True)
class MapRequest:
    """What :func:`illumination_maps` makes: the maps of ``frames`` (store frame indices, 0-based;
    None: all) collected over ``windows`` from their first ``batches`` done batches ((n_frames,)
    per store frame; None: every done batch; a segment uses the batches that make up its N_frame,
    pipeline/segments/planner.py), ``chunk`` output frames at a time."""

    windows: WindowSpec
    frames: npt.ArrayLike | None = None
    batches: npt.ArrayLike | None = None
    # the even/odd half-photon maps I1, I2 (§5.2.3) instead of the full map
    halves: bool = False
    # also each frame's mesh-based direct estimate from its own direct photons
    # (pipeline/collection/estimators.vertex_irradiance, §4), from the batch sums the gather holds already
    direct: bool = False
    chunk: int = 96


@dataclass(frozen=True)
class FrameIllumination:
    """One frame's reconstructed indirect lighting."""

    frame_index: int  # store frame index (0-based)
    irradiance: np.ndarray  # (V, 3) float64 W/m^2, or (2, V, 3) even/odd halves (MapRequest.halves)
    back: np.ndarray  # (E,) uint8: element e collected frames [f - back, f + fwd]
    fwd: np.ndarray  # (E,) uint8
    rings: np.ndarray | None  # (P, V) uint8 filter support taken (0: unfiltered), None: no filter
    direct: np.ndarray | None = None  # (V, 3) float64 the frame's own direct estimate (MapRequest.direct)


def _runs(has_photons: np.ndarray) -> list[tuple[int, int]]:
    """Maximal [start, stop) runs of frames with photons."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], has_photons.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _split_at_dark(start: int, stop: int, counts: np.ndarray, counts_from: int) -> list[tuple[int, int]]:
    """[start, stop) cut at the frames whose photons recorded no indirect light at all (a lamp
    not yet on, nothing yet to reflect it): each such frame is a run of its own, so no window
    pools light into it or its darkness into a lit frame. Condition (1) cannot see that step at an
    element a lit frame's photons reach once or twice, and an almost black frame's exposure
    would show what leaked. Rows the table does not hold count as lit (beyond any window's reach)."""
    lo, hi = max(start, counts_from), min(stop, counts_from + counts.shape[0])
    dark = np.zeros(stop - start, bool)
    if hi > lo:
        dark[lo - start:hi - start] = ~counts[lo - counts_from:hi - counts_from].any(axis=1)
    if not dark.any():
        return [(start, stop)]
    runs = [(start + a, start + b) for a, b in _runs(~dark)]
    runs += [(start + int(f), start + int(f) + 1) for f in np.flatnonzero(dark)]
    return sorted(runs)


def window_counts(store: PhotonStore, frames: Iterable[int] | None = None,
                  batches: npt.ArrayLike | None = None) -> np.ndarray:
    """(frames, E) hits per element that Condition (1), the step test and p_me read: the indirect
    hits, the photons of the map the windows collect.

    Why not every hit, as the per-frame tables of §4 count: a direct light's shadow edge sweeping
    over a moving object changes an element's direct hits tenfold in a frame while the indirect
    light there, bounced off the room, drifts smoothly; windows cut at the direct edge left those
    elements one frame of photons. On the error benchmark's defaults every run has less error and
    less error flicker with the indirect counts (docs/06-temporal.md §2; docs/11-defaults.md,
    "indirect_counts")."""
    return store.counts(kind="indirect", frames=frames, batches=batches)


def window_reach(windows: WindowSpec, config: CollectionConfig) -> int:
    """Frames of the count table either side of an output frame that its window can depend on:
    F_max/2 frames of walk plus the smoothing half-width of Condition (1)'s rates."""
    return (0 if windows.mode == "off" else windows.fmax // 2) + int(config.smoothing_frames) // 2


def check_window_options(mode: str, fmax: object) -> None:
    """``--temporal`` and ``--fmax`` as kernels/temporal.py takes them, or a one-line LoomError."""
    if mode not in MODES:
        raise LoomError(f"must be one of {', '.join(MODES)}, got {mode!r}", field="--temporal")
    try:
        ok = 0 <= int(fmax) <= 2 * MAX_HALF_FMAX
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise LoomError(f"F_max must be in [0, {2 * MAX_HALF_FMAX}], got {fmax!r}", field="--fmax")


def collection_windows(counts: np.ndarray, n_emitted: np.ndarray, frames: npt.ArrayLike, windows: WindowSpec,
                       config: CollectionConfig, *, counts_from: int = 0,
                       regions: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(len(frames), E) back and fwd windows of the requested frame indices, per run of frames
    with photons (a requested frame without photons is an error); adaptive windows make a frame
    that records no indirect light a run of its own (:func:`_split_at_dark`).

    ``counts`` holds the count-table rows ``counts_from ..`` (default the whole table); only the
    rows within :func:`window_reach` of the requested frames are read, and the windows are the
    same bits as from the whole table: every rate and walk inside the reach sees the same rows
    and the same run ends (``n_emitted`` is of every frame).

    With ``config.step_levels`` > 0, adaptive windows also stop at the abrupt changes of the element
    regions ``regions`` (pipeline/collection/regional_steps.py), which the caller must then give."""
    frames = np.asarray(frames, np.int64)
    n_emitted = np.asarray(n_emitted, np.float64)
    back = np.zeros((len(frames), counts.shape[1]), np.uint8)
    fwd = np.zeros_like(back)
    missing = frames[n_emitted[frames] <= 0] if len(frames) else frames
    if len(missing):
        raise LoomError(f"frame index(es) {missing[:5].tolist()} have no photons; shoot them first")
    reach = window_reach(windows, config)
    steps = windows.mode == "adaptive" and config.step_levels > 0
    if steps and regions is None:
        raise ValueError("config.step_levels > 0 needs the element regions")
    runs = _runs(n_emitted > 0)
    if windows.mode == "adaptive":  # fixed windows pool regardless, and read no counts
        runs = [run for start, stop in runs for run in _split_at_dark(start, stop, counts, counts_from)]
    for start, stop in runs:
        inside = np.flatnonzero((frames >= start) & (frames < stop))
        if not len(inside):
            continue
        lo, hi = int(frames[inside].min()), int(frames[inside].max()) + 1
        a, z = max(start, lo - reach), min(stop, hi + reach)
        if a < counts_from or z > counts_from + counts.shape[0]:
            raise LoomError(f"count rows [{a}, {z}) needed, [{counts_from}, "
                            f"{counts_from + counts.shape[0]}) given")
        table = counts[a - counts_from:z - counts_from]
        cuts = element_cuts(table, n_emitted[a:z], regions, config) if steps else None
        b, w = windows_cl(table, n_emitted[a:z], fmax=windows.fmax, mode=windows.mode, k_sigma=config.k_sigma,
                          smoothing_frames=config.smoothing_frames, min_extent=config.min_extent,
                          frames=(lo - a, hi - a), cuts=cuts)
        if steps:
            b, w = clamp_windows(b, w, np.arange(lo - a, hi - a), cuts)
        back[inside] = b[frames[inside] - lo]
        fwd[inside] = w[frames[inside] - lo]
    return back, fwd


def illumination_maps(store: PhotonStore, elements: ElementMesh, scene: Scene, request: MapRequest,
                      collection: CollectionConfig = CollectionConfig(), filter: FilterConfig | None = None, *,
                      times: dict[str, float] | None = None) -> Iterator[FrameIllumination]:
    """Yield the indirect illumination (the map the compositor reads) of every frame ``request``
    names, in frame order.

    Parameters
    ----------
    store : PhotonStore (pipeline/store) of the scene's photons.
    elements : the ElementMesh the photons were bucketed on; ``scene`` poses frames (vertex areas).
    request : the frames, their windows and batches, and what of each frame to give.
    collection : the windows' settings (Condition (1), the regional step test).
    filter : the adaptive filter of §5.2.5, applied where ``filter.spatial_filter``; None: unfiltered.
    times : if given, seconds spent are added to its keys ``read_s`` (stored sums or records),
        ``frame_sums_s`` (records summed where a batch has no stored sums, once per worker),
        ``windows_s``, ``sums_s`` (gather), ``filter_s`` (filter and irradiance) and ``direct_s``.
    """
    clock = StageClock(times)
    windows, batches = request.windows, request.batches
    frames = np.arange(store.n_frames) if request.frames is None else np.unique(np.asarray(request.frames, np.int64))
    if len(frames) and (frames.min() < 0 or frames.max() >= store.n_frames):
        raise LoomError(f"frame indices must be in [0, {store.n_frames})")
    if store.n_elements != elements.n_elements:
        raise LoomError(f"store has {store.n_elements} elements, the element mesh {elements.n_elements}")
    if batches is not None:
        batches = np.asarray(batches, np.int64)
    n_emitted = store.emitted(batches).astype(np.float64)
    # Only the count-table rows the windows can reach (a chunk of 16 frames reads 48 of ROOM's 135)
    reach = window_reach(windows, collection)
    first = max(0, int(frames.min()) - reach) if len(frames) else 0
    last = min(store.n_frames, int(frames.max()) + 1 + reach) if len(frames) else 0
    if windows.mode == "adaptive":
        use = None if batches is None else store.shared_batches(batches)[first:last]
        counts = window_counts(store, frames=range(first, last), batches=use)
    else:  # the table's values are not read
        counts = np.zeros((last - first, store.n_elements), np.uint32)
    back, fwd = collection_windows(counts, n_emitted, frames, windows, collection, counts_from=first,
                                   regions=step_regions(elements, collection))
    hood = _neighbourhood(elements, filter) if filter is not None and filter.spatial_filter else None
    clock.lap("windows_s")
    n_parity = 2 if request.halves else 1
    for start in range(0, len(frames), request.chunk):
        part = np.arange(start, min(start + request.chunk, len(frames)))
        f = frames[part]
        lo = int((f[:, None] - back[part]).min())
        hi = int((f[:, None] + fwd[part]).max()) + 1
        clock.lap(None)
        sums = {g: FRAME_SUMS.get(store, g, None if batches is None else int(batches[g]), "indirect", n_parity,
                                  elements, times=times) for g in range(lo, hi)}
        clock.lap(None)  # FrameSums adds its own read_s and frame_sums_s
        flux = frame_sums_flux_cl([sums[g].sums for g in range(lo, hi)], n_emitted[lo:hi], back[part],
                                  fwd[part], f - lo, elements.element_vertices, elements.n_vertices,
                                  linear=windows.mode == "adaptive")
        areas = np.stack([frame_geometry(scene, elements, store.frame_numbers[g]).vertex_areas for g in f.tolist()])
        clock.lap("sums_s")
        own = [sums[g].direct_irradiance(a) if request.direct else None for g, a in zip(f.tolist(), areas)]
        clock.lap("direct_s")
        rings = None
        if hood is not None:  # every map of the chunk in one launch
            irr, rings = adaptive_filter_cl(flux, np.broadcast_to(areas[:, None, :], flux.shape[:-1]), hood,
                                            photons=filter.filter_photons, z=filter.filter_z)
        else:
            irr = irradiance(flux, areas[:, None, :])
        clock.lap("filter_s")
        for i, (frame_index, j) in enumerate(zip(f.tolist(), part.tolist())):
            yield FrameIllumination(frame_index, irr[i] if request.halves else irr[i, 0], back[j], fwd[j],
                                    None if rings is None else rings[i], own[i])


_per_mesh: dict[int, tuple] = {}  # id(element mesh) -> (weak reference to it, {key: value})


def _mesh_cached(elements, key: tuple, compute):
    """``compute()`` once per element mesh, key and process."""
    entry = _per_mesh.get(id(elements))
    if entry is None or entry[0]() is not elements:
        entry = (weakref.ref(elements, lambda _, k=id(elements): _per_mesh.pop(k, None)), {})
        _per_mesh[id(elements)] = entry
    if key not in entry[1]:
        entry[1][key] = compute()
    return entry[1][key]


def _neighbourhood(elements, filter: FilterConfig):
    """The filter's vertex rings of an element mesh, computed once per mesh and process (a
    reconstruction task of 16 frames spent a quarter of its time on them)."""
    rings, angle = filter.filter_rings, filter.filter_angle
    return _mesh_cached(elements, ("rings", int(rings), float(angle)), lambda: neighbourhood(
        elements.element_vertices, elements.vertex_local, elements.vertex_instance, max_rings=rings,
        max_angle=angle))


def step_regions(elements: ElementMesh, config: CollectionConfig) -> list[np.ndarray] | None:
    """The element regions of the regional step test (None when ``config.step_levels`` is 0), once
    per mesh and process."""
    if not config.step_levels:
        return None
    return _mesh_cached(elements, ("steps", int(config.step_levels)),
                        lambda: region_levels(elements, config.step_levels))
