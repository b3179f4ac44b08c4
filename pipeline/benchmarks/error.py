"""``loom bench error SCENE``: run time against error, for our method and the ways a user would otherwise
render the same animation.

Every method is a real ``loom render`` (pipeline/run/render.py) of the same frames on one LocalCluster,
timed whole (wall; CPU = this process plus every worker process), into a fresh output folder:

* per-frame: ``--photons N --temporal off``, the traditional approach of §6;
* fixed windows: ``--photons N --fmax F --temporal fixed`` (Fig. 3b);
* adaptive windows: ``--photons N --fmax F --temporal adaptive`` (§5.1, fixed N_frame and F_max);
* guided: ``--photons auto`` (the coordinator of §5.2) at several d_thr, exactly as ``loom render``
  runs it by default: the config's own doubling cap (``n_frame_max``, 1,280,000 by default), no override.

The reference is per-frame photon tracing with no temporal reuse, ``--reference-factor`` (>= 50) x the
largest *budget* per frame, not x the largest N_frame the guided loop reaches nor x its cap. Why: 50x
the default cap is 64,000,000 photons a frame, which on ROOM's quick plan (20 frames, 2 seeds) is
2.56 G photons, 25-35 minutes of tracing on the 2-core benchmark machine against about 2 minutes
for the rest of the run; and a reference sized by the guided run's reach would depend on the outcome
of the runs it judges (a config that climbs higher would be judged against another reference, and the
cache in ``OUT/references/`` could not be shared between configs). So the reference is always >= 50x
every fixed-budget run (per-frame, fixed, adaptive), the comparisons the 50x rule was made for, and
the output (and ``error.json``'s ``reference.basis``) says the largest N_frame the guided runs reached
and how many times that the reference holds: where that is under 50, the guided run's error is
partly the reference's noise (the printed floor bounds what can be resolved), and
``--reference-factor`` buys a closer reference (a 250x quick reference, 5,000,000 photons a frame,
takes about 2 minutes).
The reference is traced on the workers straight into vertex maps (:func:`reference_map`:
the same tracer, elements and estimator as a render, so discretisation is common to both and every
difference is noise or temporal bias), twice with different seeds: the second reference against
the first is the noise floor printed beside every error. Every frame of one reference draws the
same random numbers (common random numbers: the Philox stream of the range's first frame, posed
at its own frame), so where a frame's scene equals the one before, so does its reference noise:
the reference's noise stays out of the error's *flicker*, where independent per-frame noise would
add sqrt(2) x its amplitude to every method's figure (docs/12-error-benchmark.md
§2). Each frame alone is still an independent-seed estimate, so every per-frame measure
and the floor are as before. The references are kept in
``OUT/references/`` (:func:`reference_key`: scene, elements, frames, photons, seeds, photon depth and
the tracer's source), so a rerun with another ``--config`` or other budgets of the same reference
does not trace them again: they are most of a full run's time.

Measures per run (pipeline/benchmarks/error_measures.py), all frames: relative L2 of the indirect
vertex irradiance; after one frozen tone mapping (Ward's scale at the log-average luminance of the
reference's frames, pipeline/frames/perceived.py) RMSE and mean relative error of the displayed frames
and d_AQM (every ``--aqm-every``-th frame, on the workers); on the same frames the FLIP mean of the
frames as their PNGs show them at that adaptation (error_measures.displayed_flip, as ``loom bench
spp`` computes it, at the AQM's pixels per degree); the flicker of the error field
(vertex maps and displayed frames) and of the run's photon noise alone (:func:`photon_noise`); the
Fig. 3 highlight's energy (ROOM: floor vertices within 0.5 m under the aircraft,
tests/collection/test_room.py; elsewhere the brightest 2 % of the reference's indirect light)
against the reference's; the lag after an abrupt lighting change.
Frames are composited here from each run's indirect maps with the same camera samples and direct
light (workers/composite.py), so image differences are in the indirect light only.

The abrupt change: built-in ROOM and CORNELL get a STEP jump of one light (``EVENTS``) at the middle
frame of the benchmark's range, written into the benchmark's copy of the scene; for any other scene
the largest frame-to-frame change of the reference is taken.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from pipeline.collection.estimators import vertex_irradiance
from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps
from pipeline.config import PhotonConfig, RenderConfig, SegmentConfig
from pipeline.errors import LoomError
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.frames.map_hits import MapHits
from pipeline.frames.perceived import display_values, displayed_difference
from pipeline.frames.settings import RenderSettings
from pipeline.frames.tonemap import log_average, luminance
from pipeline.photons.raycast import caster_for
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.run.cluster import connect
from pipeline.run.render import RenderRequest, render
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import BUILTIN_SCENES
from pipeline.scene.scene_cache import load_elements, load_scene
from pipeline.scene.timeline import Timeline
from pipeline.segments.planner import batches_in_use
from pipeline.segments.records import read_records
from pipeline.store import PhotonStore
from pipeline.store.illumination import IlluminationMaps

from . import error_measures as em
from .machine import announce

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from distributed import Client  # imported once a cluster starts

    from pipeline.config import RenderConfig
    from pipeline.scene import ElementMesh, FrameState, Scene

# Built-in scene -> (light node, offset of its STEP jump in metres): the abrupt lighting change
EVENTS = {"room": ("corner_spot", (-2.0, 0.0, 1.5)), "cornell": ("ceiling_lamp", (-0.3, 0.0, 0.0))}
# Kernels that run on stored photons only (windows, gather, filter): not the reference's
RECONSTRUCTION_KERNELS = ("temporal", "gather", "filter")
# What a reference map depends on besides its inputs: the tracer, the estimator, the scene and the
# kernels (but those that run on stored photons only); the compositor (pipeline/frames/) is not in it
REFERENCE_SOURCES = ("pipeline/photons", "pipeline/collection/estimators.py", "kernels", "pipeline/scene")
REFERENCE_BATCH = 250_000  # photons traced per call into a reference map (bounded worker memory)
REFERENCE_SEEDS = (101, 202)  # a reference's two Philox seeds: errors against the first, the second its noise floor
# The methods compared; per-frame rendering is the baseline every ratio is taken against
METHODS = ("per-frame", "fixed", "adaptive", "guided")


@dataclass(frozen=True)
class Plan:
    """What one ``loom bench error`` run renders."""

    frames: tuple[int, int]
    budgets: tuple[int, ...]  # N_frame of the fixed-budget methods; the largest sizes the reference
    fmax: int  # F_max of fixed and adaptive windows
    d_thr: tuple[float, ...]
    width: int = 320
    height: int = 240
    spp: int = RenderSettings.spp  # loom render's
    reference_factor: int = 50
    aqm_every: int = 1
    methods: tuple[str, ...] = METHODS  # a subset (with per-frame) shortens a run to what is compared

    @property
    def event(self) -> int:
        return (self.frames[0] + self.frames[1] + 1) // 2

    @property
    def reference_photons(self) -> int:
        return self.reference_factor * max(self.budgets)


QUICK = {"room": Plan((61, 80), (5_000, 10_000, 20_000), 14, (0.03, 0.8), aqm_every=4),
         "cornell": Plan((1, 30), (5_000, 10_000, 20_000), 14, (0.03, 0.8), aqm_every=4)}
FULL = {"room": Plan((46, 90), (10_000, 20_000, 40_000, 80_000), 30, (0.03, 0.1, 0.3)),
        "cornell": Plan((1, 30), (10_000, 20_000, 40_000, 80_000), 30, (0.03, 0.1, 0.3))}


def write_scene(name: str, path: Path, event: int) -> Path:
    """The built-in scene ``name`` with its light jumping at frame ``event`` (``EVENTS``)."""
    b = BUILTIN_SCENES[name]()
    if name in EVENTS:
        node_name, offset = EVENTS[name]
        (node,) = [i for i, n in enumerate(b.gltf.nodes) if n.name == node_name]
        base = np.asarray(b.gltf.nodes[node].translation or (0.0, 0.0, 0.0), float)
        extras = b.gltf.scenes[0].extras["photonloom"]
        # Half a frame before the event's time: a float32 key time exactly on a frame could land after it
        t = Timeline(fps=extras["fps"], frames=extras["frames"]).time(event) - 0.5 / extras["fps"]
        b.add_animation("bench_light_jump", node, "translation", [0.0, t], [base, base + offset],
                        interpolation="STEP")
    return b.write(path)


def reference_map(*, scene_path: str, scene_hash: str, element_size: float, frame: int, n_photons: int,
                  seed: int, stream: int, max_depth: int) -> np.ndarray:
    """Dask task: (V, 3) indirect vertex irradiance of ``n_photons`` photons traced in the scene as
    posed at ``frame``, drawn from the Philox stream (``seed``, ``stream``), in batches summed in
    float64 (no store: nothing is reused across frames; a common ``stream`` for every frame makes
    the frames' noise alike where their scenes are)."""
    scene = load_scene(scene_path, scene_hash)
    elements = load_elements(scene_path, scene_hash, element_size)
    state = scene.pose_frame(frame)
    areas = elements.vertex_areas(state)
    total = np.zeros((elements.n_vertices, 3))
    for start in range(0, n_photons, REFERENCE_BATCH):
        n = min(REFERENCE_BATCH, n_photons - start)
        b = trace_batch(state, elements, PhotonRange(stream, start, n), PhotonConfig(seed=seed, photon_depth=max_depth))
        total += vertex_irradiance(*b.indirect(), elements, areas, 1)
    return total / n_photons


def reference_key(*, scene_hash: str, element_size: float, frames: tuple[int, int], n_photons: int,
                  seeds: Sequence[int], max_depth: int) -> str:
    """Name of a cached pair of references: everything :func:`reference_map` reads, and the source of
    the code that traces and estimates (``REFERENCE_SOURCES``), so a changed tracer never meets a
    stale reference and a changed compositor does not cost a new one."""
    h = hashlib.sha256(json.dumps([scene_hash, element_size, list(frames), n_photons, list(seeds), max_depth,
                                   "common random numbers"]).encode())
    root = Path(__file__).resolve().parents[2]
    for source in REFERENCE_SOURCES:
        path = root / source
        for f in sorted(path.rglob("*")) if path.is_dir() else [path]:
            if f.suffix in (".py", ".cl") and not (source == "kernels" and f.stem in RECONSTRUCTION_KERNELS):
                h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:20]


def load_references(path: Path) -> tuple[np.ndarray, float, float] | None:
    """``(refs, wall_s, cpu_s)`` of a cached reference pair, or None when there is none."""
    if not path.exists():
        return None
    with np.load(path) as z:
        return z["refs"], float(z["wall_s"]), float(z["cpu_s"])


def save_references(path: Path, refs: np.ndarray, wall_s: float, cpu_s: float) -> None:
    """Write atomically: a kill leaves the old file or none, never half of one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as f:
        np.savez(f, refs=refs, wall_s=wall_s, cpu_s=cpu_s)
    os.replace(tmp, path)


def displayed_measures(test: np.ndarray, ref: np.ndarray, adaptation: float, ppd: float) -> tuple[float, float]:
    """Dask task: d_AQM (%) of two linear frames as the viewer sees them (pipeline/frames/perceived.py), and
    their FLIP mean as their PNGs show them (error_measures.displayed_flip), both at ``adaptation``."""
    return float(displayed_difference(test, ref, adaptation).d_aqm), em.displayed_flip(test, ref, adaptation, ppd)


def _cpu_seconds(client: Client) -> float:
    return time.process_time() + sum(client.run(time.process_time).values())


def run_method(client: Client, scene_path: Path, out: Path, plan: Plan, *, method: str, n_photons: int | None,
               config: RenderConfig, fmax: int | None, temporal: str, scene: Scene, elements: ElementMesh) -> dict:
    """One timed ``loom render`` of the plan's frames (``scene`` and ``elements`` read from ``scene_path``);
    its indirect maps, their photon noise (:func:`photon_noise`) and what it cost."""
    settings = RenderSettings(width=plan.width, height=plan.height, spp=plan.spp)
    cpu0, t0 = _cpu_seconds(client), time.perf_counter()
    report = render(RenderRequest(scene_path=scene_path, frames=f"{plan.frames[0]}-{plan.frames[1]}", out_dir=out,
                                  settings=settings, n_photons=n_photons, config=config, temporal=temporal, fmax=fmax),
                    scheduler=client.scheduler.address)
    wall = time.perf_counter() - t0
    cpu = _cpu_seconds(client) - cpu0
    store = PhotonStore.open(str(out / "photons.zarr"))
    sources = {store.source_frame(i) for i in range(store.n_frames)}
    photons = sum(store.photons_emitted(i) for i in sources)
    maps = IlluminationMaps.open(str(out / "photons.zarr"))
    indirect = np.stack([np.asarray(maps.read(f - 1), np.float64) for f in range(plan.frames[0], plan.frames[1] + 1)])
    noise = photon_noise(out, store, scene, elements, plan, config)
    own = None
    if n_photons is None:  # the guided run: a frame's own photon noise, unfiltered, for the hindsight bound
        alone = photon_noise(out, store, scene, elements, plan, config, windows=WindowSpec("off", 0), filtered=False)
        own = np.mean(np.sum(np.square(alone), axis=-1), axis=0)
    shutil.rmtree(out)
    return {"method": method, "n_photons": n_photons, "fmax": fmax, "d_thr": config.segments.d_thr if n_photons is None
            else None, "wall_s": wall, "cpu_s": cpu, "photons": photons, "segments": report["segments"],
            "indirect": indirect, "noise": noise, "noise_var": own}


def photon_noise(out: Path, store: PhotonStore, scene: Scene, elements: ElementMesh, plan: Plan,
                 config: RenderConfig, *, windows: WindowSpec | None = None, filtered: bool = True) -> np.ndarray:
    """(T, V, 3) half the difference of each frame's even and odd half maps (§5.2.3), collected as the
    render's segments collected its maps (their windows, photons and filter, from their records): the
    photon noise in the windows the run chose. What it leaves of the run's flicker is bias, the
    windows' own noise and the reference's (docs/12-error-benchmark.md §3). ``windows``: these
    instead of the segments'; ``filtered``: False leaves out the spatial filter."""
    records = read_records(out)
    targets: dict[int, int] = {}
    for rec in records:
        targets.update(rec.targets())
    use = batches_in_use(store, targets)
    first, last = plan.frames
    noise = {}
    for rec in records:
        frames = [f - 1 for f in range(max(rec.start, first), min(rec.end, last) + 1)]
        request = MapRequest(windows or WindowSpec(rec.temporal, rec.windows_fmax), frames, batches=use, halves=True)
        for lit in illumination_maps(store, elements, scene, request, config.collection,
                                     config.filter if filtered else None):
            noise[lit.frame_index + 1] = (lit.irradiance[0] - lit.irradiance[1]) / 2.0
    return np.stack([noise[f] for f in range(first, last + 1)])


TRACED_BYTES = 4 << 30  # camera paths kept for relighting (about 25 MB a 320x240 frame at 8 spp)


class Evaluation:
    """The reference's frames, and every measure of a run's maps against them."""

    def __init__(self, client: Client, scene: Scene, elements: ElementMesh, plan: Plan, refs: np.ndarray,
                 highlight: Sequence[np.ndarray]) -> None:
        self.client, self.plan, self.refs = client, plan, refs
        self.frames = list(range(plan.frames[0], plan.frames[1] + 1))
        self.states = [scene.pose_frame(f) for f in self.frames]
        self.casters = [caster_for(s) for s in self.states]
        self.areas = np.stack([elements.vertex_areas(s) for s in self.states])
        self.highlight = highlight
        self.elements = elements
        self._traced: dict[int, tuple[np.ndarray, MapHits]] = {}  # frame index -> direct light, map hits
        self._traced_bytes = 0
        self.ref_images = self.images(refs[0])
        self.adaptation = log_average(luminance(self.ref_images))  # the frozen tone mapping's L_wa
        self.ref_displayed = self.displayed(self.ref_images)
        self.ppd = em.frame_ppd(plan.width, plan.height)  # FLIP's viewing distance, the AQM's
        self.floor_flicker = None  # per interval, set from the second reference (see run)
        self.aqm_frames = sorted(set(range(0, len(self.frames), plan.aqm_every)) | {self.event_index})

    @property
    def event_index(self) -> int:
        return self.plan.event - self.plan.frames[0]

    def images(self, maps: np.ndarray) -> np.ndarray:
        return np.stack([self._render(i, m) for i, m in enumerate(maps)])

    def _render(self, i: int, irradiance: np.ndarray) -> np.ndarray:
        """Frame ``i`` lit by ``irradiance``: every method's frame is seen along the same camera
        paths, so the first render of a frame keeps where they read the map and later ones relight
        them (pipeline/frames/map_hits.py, the same bits), while :data:`TRACED_BYTES` allows."""
        kept = self._traced.get(i)
        if kept is not None:
            direct, hits = kept
            return direct + hits.indirect(self.elements, irradiance)
        plan = self.plan
        img = render_frame(self.states[i], self.elements, irradiance,
                           CameraPaths(plan.width, plan.height, plan.spp, 0, self.frames[i]), caster=self.casters[i],
                           record_hits=self._traced_bytes < TRACED_BYTES)
        if img.map_hits is not None:
            self._traced[i] = (img.direct, img.map_hits)
            self._traced_bytes += img.map_hits.nbytes + img.direct.nbytes
        return img.beauty

    def displayed(self, images: np.ndarray) -> np.ndarray:
        return display_values(images, self.adaptation)

    def measure(self, maps: np.ndarray, noise: np.ndarray | None = None, noise_var: np.ndarray | None = None) -> dict:
        """Every measure of ``maps`` (T, V, 3) against the reference; with ``noise`` (their photon
        noise, :func:`photon_noise`) also the flicker that noise alone has; with ``noise_var`` (V,), a
        frame's own photon-noise variance at the run's photons, the RMS of the run's flicker over the
        frame pairs and the bound any windows could reach there with hindsight of the light, measured
        like the run's against the first reference (error_measures.hindsight_flicker)."""
        refs, areas = self.refs[0], self.areas
        images = self.images(maps)
        shown = self.displayed(images)
        pairs = self.client.scatter([images[i] for i in self.aqm_frames]
                                    + [self.ref_images[i] for i in self.aqm_frames])
        n = len(self.aqm_frames)
        futures = self.client.map(displayed_measures, pairs[:n], pairs[n:], [self.adaptation] * n, [self.ppd] * n,
                                  pure=False)
        rel = [em.relative_l2(m, r, a) for m, r, a in zip(maps, refs, areas)]
        img = np.array([em.image_errors(s, r) for s, r in zip(shown, self.ref_displayed)])
        hl = [em.region_energy(m, a, h) / em.region_energy(r, a, h) - 1.0
              for m, r, a, h in zip(maps, refs, areas, self.highlight)]
        keep = np.arange(len(maps) - 1) != self.event_index - 1  # the change itself is the lag's, not flicker
        fl = em.flicker(maps, refs, areas)[keep]
        own = np.array([em.relative_l2(maps[t], maps[t - 1], areas[t]) for t in range(1, len(maps))])[keep]
        floor = self.floor_flicker if self.floor_flicker is not None else np.zeros_like(fl)
        net = np.sqrt(np.maximum(fl ** 2 - floor ** 2 / 2.0, 0.0))
        response = em.step_response(maps, refs, areas, self.event_index)
        lag, reached = em.lag(response)
        d_aqm, flip = (list(x) for x in zip(*self.client.gather(futures)))
        aqm_frames = [self.frames[i] for i in self.aqm_frames]
        return {"rel_l2": float(np.mean(rel)), "rmse": float(img[:, 0].mean()), "mean_rel": float(img[:, 1].mean()),
                "d_aqm": float(np.mean(d_aqm)), "flip": float(np.mean(flip)), "flicker": float(np.mean(fl)),
                "flicker_net": float(np.mean(net)),
                "flicker_noise": None if noise is None else float(np.mean(em.flicker(refs + noise, refs, areas)[keep])),
                "flicker_rms": float(np.sqrt(np.mean(fl ** 2))),
                "flicker_hindsight": None if noise_var is None else em.hindsight_flicker(
                    refs, noise_var, areas, self.event_index),
                "change": float(np.mean(own)),
                "image_flicker": float(np.mean(em.image_flicker(shown, self.ref_displayed)[keep])),
                "highlight": float(np.mean(hl)), "lag": lag, "lag_reached": reached,
                "per_frame": {"rel_l2": rel, "flicker": fl.tolist(), "response": response.tolist(),
                              "d_aqm": dict(zip(aqm_frames, d_aqm)), "flip": dict(zip(aqm_frames, flip))}}


def highlight_regions(scene: Scene, elements: ElementMesh, states: Sequence[FrameState], refs: np.ndarray,
                      areas: np.ndarray) -> tuple[list[np.ndarray], str]:
    """Per frame the Fig. 3 highlight's vertices, and how they were chosen."""
    names = [inst.name.split("/")[0] for inst in scene.instances]
    if "aircraft_body" in names and "floor" in names:
        body, floor = names.index("aircraft_body"), names.index("floor")
        out = []
        for s in states:
            pos = elements.vertex_positions(s)
            c = s.instance_matrices[body][:3, 3]
            out.append((elements.vertex_instance == floor) & (np.hypot(pos[:, 0] - c[0], pos[:, 2] - c[2]) < 0.5))
        return out, "floor within 0.5 m under the aircraft (Fig. 3)"
    return [em.brightest_region(r, a) for r, a in zip(refs, areas)], "brightest 2 % of the reference's indirect light"


def summarise(runs: list[dict], clock: str = "wall_s", slope: float | None = None) -> dict:
    """Every other run against per-frame rendering: per-frame's error at its time (``clock``: wall_s or
    cpu_s) and the time per-frame rendering needs for its error (photons on the per-frame cost line,
    error against photons log-log: error_measures.equal_time / equal_error), and their ratios.
    ``slope``: seconds a photon on that clock from the reference, where the runs' own jitter hides it."""
    base = [r for r in runs if r["method"] == "per-frame"]
    photons, times = [r["photons"] for r in base], [r[clock] for r in base]
    a, b = em.cost_model(photons, times, slope)
    rows = []
    for r in runs:
        if r["method"] == "per-frame":
            continue
        row = {"run": r["label"], "method": r["method"], clock: r[clock]}
        for key in ("d_aqm", "flip", "rel_l2", "flicker", "flicker_net", "image_flicker"):
            at_t, extra = em.equal_time(photons, times, [b_["measures"][key] for b_ in base], r[clock], slope)
            row[key] = {"run": r["measures"][key], "per_frame_at_equal_time": at_t, "extrapolated": extra,
                        "ratio": None if not at_t else r["measures"][key] / at_t}
        for key in ("d_aqm", "rel_l2"):
            t_eq, extra = em.equal_error(photons, times, [b_["measures"][key] for b_ in base], r["measures"][key],
                                          slope)
            row[f"speedup_at_equal_{key}"] = {"per_frame_s": t_eq, "speedup": t_eq / r[clock],
                                              "extrapolated": extra}
        rows.append(row)
    return {"per_frame_cost": {"fixed_s": a, "s_per_million_photons": b * 1e6}, "rows": rows}


def plot(result: dict, path: Path) -> list[Path]:
    """Error against time: (a) d_AQM and (b) relative L2 against wall seconds per method, the
    reference's noise floor dashed; (c) relative L2 per frame of each method's largest run, the
    abrupt change marked; (d) error flicker against CPU seconds, each run's photon noise alone
    dotted, and a fifth of per-frame rendering's, the target a run must be under at its CPU time.
    PNG and SVG."""
    import matplotlib  # heavy: only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy: only when drawing

    runs, floor = result["runs"], result["reference"]["floor"]
    fig, axes = plt.subplots(1, 4, figsize=(21, 4.8))
    colours = {"per-frame": "tab:red", "fixed": "tab:orange", "adaptive": "tab:blue", "guided": "tab:green"}
    for ax, key, label in ((axes[0], "d_aqm", "d_AQM vs reference (%)"), (axes[1], "rel_l2", "relative L2, indirect")):
        for method, colour in colours.items():
            pts = [(r["wall_s"], r["measures"][key]) for r in sorted(runs, key=lambda r: r["photons"])
                   if r["method"] == method]  # joined in budget order: wall times jitter on a loaded machine
            if pts:
                ax.plot(*zip(*pts), "o-", color=colour, label=method)
        ax.axhline(max(floor[key], 1e-4), color="grey", ls="--", label="reference noise floor")
        ax.set(xscale="log", yscale="log", xlabel="wall seconds (whole render)", ylabel=label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    ax = axes[2]
    frames = np.arange(result["plan"]["frames"][0], result["plan"]["frames"][1] + 1)
    for method, colour in colours.items():
        mine = [r for r in runs if r["method"] == method]
        if mine:
            r = max(mine, key=lambda r: r["photons"])
            ax.plot(frames, r["measures"]["per_frame"]["rel_l2"], color=colour, label=r["label"])
    ax.plot(frames, result["reference"]["floor_per_frame"], color="grey", ls="--", label="reference noise floor")
    ax.axvline(result["event"]["frame"], color="k", lw=0.8, ls=":", label="abrupt lighting change")
    ax.set(yscale="log", xlabel="frame", ylabel="relative L2, indirect")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[3]
    for method, colour in colours.items():
        mine = sorted((r for r in runs if r["method"] == method), key=lambda r: r["photons"])
        if not mine:
            continue
        ax.plot([r["cpu_s"] for r in mine], [r["measures"]["flicker"] for r in mine], "o-", color=colour, label=method)
        noise = [(r["cpu_s"], r["measures"].get("flicker_noise")) for r in mine]
        if all(n is not None for _, n in noise):
            ax.plot(*zip(*noise), "x:", color=colour)
        if method == "per-frame":  # a fifth of its flicker at equal CPU time, over every run's time
            slope = result["comparison"]["cpu_s"]["per_frame_cost"]["s_per_million_photons"] / 1e6
            base = [[r[k] for r in mine] for k in ("photons", "cpu_s")] + [[r["measures"]["flicker"] for r in mine]]
            ts = np.geomspace(min(r["cpu_s"] for r in runs), max(r["cpu_s"] for r in runs), 32)
            fifth = [(t, e / 5) for t in ts for e in [em.equal_time(*base, t, slope)[0]] if e is not None]
            if fifth:
                ax.plot(*zip(*fifth), "--", color=colour, lw=0.8, label="1/5 of per-frame's at equal CPU (target)")
    ax.plot([], [], "x:", color="k", label="photon noise alone")
    ax.axhline(floor["flicker"], color="grey", ls="--", label="reference noise floor")
    ax.set(xscale="log", yscale="log", xlabel="CPU seconds (this process and the workers)",
           ylabel="error flicker, indirect")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle(f"loom bench error {result['scene']}: error against time")
    fig.tight_layout()
    written = []
    for suffix in (".png", ".svg"):
        p = path.with_suffix(suffix)
        fig.savefig(p, dpi=110)
        written.append(p)
    plt.close(fig)
    return written


def _ratio(d: dict) -> str:
    if d["ratio"] is None:
        return "n/a (per-frame cannot finish)"
    return f"{d['ratio']:.3f}{'*' if d['extrapolated'] else ''}"


def _against(d: dict, digits: int) -> str:
    """A run's figure, per-frame rendering's at equal time and their ratio (summarise's row entry)."""
    at_t = d["per_frame_at_equal_time"]
    return f"{d['run']:.{digits}f} vs {'n/a' if at_t is None else f'{at_t:.{digits}f}'}: {_ratio(d)}"


def _optional(x: float | None) -> str:
    return "" if x is None else f"{x:.4f}"


def _table(echo: Callable[[str], None], result: dict) -> None:
    floor = result["reference"]["floor"]
    echo("")
    echo("| run | wall s | CPU s | photons | rel L2 | RMSE | mean rel | d_AQM % | FLIP | flicker | of it photon noise "
         "| image flicker | highlight | lag (frames) |")
    echo("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    echo(f"| reference noise floor (2nd seed) | {result['reference']['wall_s']:.1f} | | "
         f"{result['reference']['photons']:,} x 2 | {floor['rel_l2']:.4f} | {floor['rmse']:.4f} "
         f"| {floor['mean_rel']:.4f} | {floor['d_aqm']:.2f} | {floor['flip']:.4f} | {floor['flicker']:.4f} | "
         f"| {floor['image_flicker']:.4f} | {100 * floor['highlight']:+.1f} % | {floor['lag']} |")
    for r in result["runs"]:
        m = r["measures"]
        lag = f"{m['lag']}" if m["lag_reached"] else f">= {m['lag']}"
        echo(f"| {r['label']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['photons']:,} | {m['rel_l2']:.4f} "
             f"| {m['rmse']:.4f} | {m['mean_rel']:.4f} | {m['d_aqm']:.2f} | {m['flip']:.4f} | {m['flicker']:.4f} "
             f"| {_optional(m.get('flicker_noise'))} | {m['image_flicker']:.4f} | {100 * m['highlight']:+.1f} % "
             f"| {lag} |")
    echo("")
    for clock, name in (("cpu_s", "CPU"), ("wall_s", "wall")):
        comparison = result["comparison"][clock]
        cost = comparison["per_frame_cost"]
        echo(f"\nagainst per-frame rendering at equal {name} time (per-frame cost line: {cost['fixed_s']:.1f} s + "
             f"{cost['s_per_million_photons']:.2f} s per million photons)")
        echo("| run | d_AQM, per-frame's at equal time: ratio | FLIP, per-frame's at equal time: ratio "
             "| flicker ratio | net flicker ratio | image flicker ratio | speed-up at equal d_AQM | at equal rel L2 |")
        echo("|---|---|---|---|---|---|---|---|")
        for s in comparison["rows"]:
            up = [f"{s[k]['speedup']:.2f}x{'*' if s[k]['extrapolated'] else ''}"
                  for k in ("speedup_at_equal_d_aqm", "speedup_at_equal_rel_l2")]
            echo(f"| {s['run']} | {_against(s['d_aqm'], 2)} | {_against(s['flip'], 4)} | {_ratio(s['flicker'])} "
                 f"| {_ratio(s['flicker_net'])} | {_ratio(s['image_flicker'])} | {up[0]} | {up[1]} |")
    echo("(* per-frame figure extrapolated beyond its runs along the power law of the two nearest)")
    for r in result["runs"]:
        bound, rms = r["measures"].get("flicker_hindsight"), r["measures"]["flicker_rms"]
        if bound is None:
            continue
        ratio = next(x["flicker"]["ratio"] for x in result["comparison"]["cpu_s"]["rows"] if x["run"] == r["label"])
        at_cpu = "" if not ratio else f", a flicker ratio of about {ratio * bound / rms:.2f} at its CPU time"
        echo(f"{r['label']}: windows chosen with hindsight of the light would flicker {bound:.4f} at its photons "
             f"(RMS over the frame pairs; the run {rms:.4f}){at_cpu} (docs/12-error-benchmark.md §7)")


def run(scene_name: str, plan: Plan, out_dir: Path, *, workers: int = 2, config: RenderConfig | None = None,
        echo: Callable[[str], None] = click.echo) -> dict:
    """Render, measure, print the tables, write ``error.json`` and ``error.png``/``.svg`` in ``out_dir``.
    ``config`` (a RenderConfig; default the defaults) is every method's; the reference has no
    temporal collection and reads only its photon depth."""
    if plan.reference_factor < 50:
        raise LoomError(f"must be at least 50, got {plan.reference_factor}", field="--reference-factor")
    em.flip_evaluator()  # FLIP is one of the measures: refused before any tracing if it is missing
    out_dir.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="loom-bench-error-", dir=out_dir) as tmp:
        tmp = Path(tmp)
        builtin = scene_name in BUILTIN_SCENES
        path = write_scene(scene_name, tmp / f"{scene_name}.glb", plan.event) if builtin else Path(scene_name)
        scene = read_scene(path)
        first, last = plan.frames
        if not (scene.timeline.first <= first < last <= scene.timeline.last):
            raise LoomError(f"frames {first}-{last} are not inside the scene's {scene.timeline.first}-"
                            f"{scene.timeline.last}", path=str(path), field="--frames")
        elements = ElementMesh.build(scene)
        config = config or RenderConfig()
        echo(f"loom bench error {Path(path).stem}: frames {first}-{last}, {plan.width}x{plan.height}, {plan.spp} spp, "
             f"budgets {', '.join(f'{n:,}' for n in plan.budgets)}, F_max {plan.fmax}, d_thr "
             f"{', '.join(f'{d:g}' for d in plan.d_thr)}; reference {plan.reference_photons:,} photons a frame "
             f"x 2 seeds; {elements.n_elements:,} elements; {workers} workers")
        machine = {"before": announce(tmp, "before", echo)}  # equal-time ratios move with it
        seeds = REFERENCE_SEEDS
        cache = out_dir / "references" / (reference_key(
            scene_hash=scene.scene_hash, element_size=elements.element_size, frames=plan.frames,
            n_photons=plan.reference_photons, seeds=seeds, max_depth=config.photons.photon_depth) + ".npz")
        with connect("local", workers) as client:
            cached = load_references(cache)
            if cached is not None:
                refs, ref_s, ref_cpu = cached
                echo(f"references: reused {cache} (traced in {ref_s:.1f} s)")
            else:
                cpu0, t0 = _cpu_seconds(client), time.perf_counter()
                refs = []
                for seed in seeds:
                    futures = [client.submit(reference_map, scene_path=str(Path(path).resolve()),
                                             scene_hash=scene.scene_hash, element_size=elements.element_size,
                                             frame=f, n_photons=plan.reference_photons, seed=seed,
                                             stream=first, max_depth=config.photons.photon_depth, pure=False)
                               for f in range(first, last + 1)]
                    refs.append(np.stack(client.gather(futures)))
                refs = np.stack(refs)
                ref_s, ref_cpu = time.perf_counter() - t0, _cpu_seconds(client) - cpu0
                save_references(cache, refs, ref_s, ref_cpu)
                echo(f"references: {ref_s:.1f} s, kept in {cache}")
            states = [scene.pose_frame(f) for f in range(first, last + 1)]
            areas = np.stack([elements.vertex_areas(s) for s in states])
            highlight, highlight_is = highlight_regions(scene, elements, states, refs[0], areas)
            ev = Evaluation(client, scene, elements, plan, refs, highlight)
            if not builtin or scene_name not in EVENTS:
                t, size = em.largest_change(refs[0], areas)
                event = first + t
            else:
                event = plan.event
                size = em.largest_change(refs[0][ev.event_index - 1:ev.event_index + 1],
                                         areas[ev.event_index - 1:ev.event_index + 1])[1]
            echo(f"abrupt lighting change at frame {event} ({100 * size:.0f} % of the indirect light); "
                 f"highlight: {highlight_is}")
            floor = ev.measure(refs[1])
            ev.floor_flicker = np.asarray(floor["per_frame"]["flicker"])
            specs = [("per-frame", dict(n_photons=n, fmax=0, temporal="off", config=config)) for n in plan.budgets]
            specs += [(m, dict(n_photons=n, fmax=plan.fmax, temporal=m, config=config))
                      for m in ("fixed", "adaptive") if m in plan.methods for n in plan.budgets]
            specs += [("guided", dict(n_photons=None, fmax=None, temporal="adaptive",
                                      config=config.replace(segments=config.segments.replace(d_thr=d))))
                      for d in plan.d_thr if "guided" in plan.methods]
            # Warm-up, not timed: the workers' first render builds kernels and caches the first run would pay
            run_method(client, path, tmp / "warm-up", plan, **{**specs[0][1], "method": "warm-up"}, scene=scene,
                       elements=elements)
            runs = []
            for i, (method, kw) in enumerate(specs):
                r = run_method(client, path, tmp / f"run-{i}", plan, method=method, **kw, scene=scene,
                               elements=elements)
                r["measures"] = ev.measure(r.pop("indirect"), r.pop("noise"), r.pop("noise_var"))
                r["label"] = _label(r)
                echo(f"  {r['label']}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} s CPU, {r['photons']:,} photons; "
                     f"rel L2 {r['measures']['rel_l2']:.4f}, d_AQM {r['measures']['d_aqm']:.2f} %, "
                     f"FLIP {r['measures']['flip']:.4f}, flicker {r['measures']['flicker']:.4f} (photon noise "
                     f"{r['measures']['flicker_noise']:.4f}), lag {r['measures']['lag']}")
                runs.append(r)
        machine["after"] = announce(tmp, "after", echo)
    ref_photons = 2 * plan.reference_photons * (last - first + 1)
    basis = reference_basis(plan, runs, config.segments, ref_photons, ref_s)
    if basis["guided_n_frame"]:
        echo(basis["statement"])
    result = {"scene": Path(path).stem, "plan": {**plan.__dict__, "event": plan.event}, "config": config.to_dict(),
              "elements": elements.n_elements, "workers": workers, "machine": machine, "adaptation": ev.adaptation,
              "event": {"frame": event, "size": size}, "highlight_region": highlight_is,
              "reference": {"photons": plan.reference_photons, "seeds": list(seeds), "file": str(cache),
                            "wall_s": ref_s, "cpu_s": ref_cpu, "basis": basis,
                            "floor": {k: v for k, v in floor.items() if k != "per_frame"},
                            "floor_per_frame": floor["per_frame"]["rel_l2"]},
              "runs": runs, "comparison": {c: summarise(runs, c, {"cpu_s": ref_cpu, "wall_s": ref_s}[c] / ref_photons)
                                          for c in ("cpu_s", "wall_s")}, "total_s": time.perf_counter() - t_start}
    _table(echo, result)
    (out_dir / "error.json").write_text(json.dumps(result, indent=1, default=float))
    written = plot(result, out_dir / "error")
    echo(f"\nwrote {out_dir / 'error.json'}, {', '.join(str(p) for p in written)} ({result['total_s']:.0f} s)")
    return result


def reference_basis(plan: Plan, runs: list[dict], config: SegmentConfig, ref_photons: int, ref_s: float) -> dict:
    """Which budget the reference was sized by and why (module docstring): the largest N_frame the guided
    runs reached, how many times that the reference holds, and what 50x the config's cap would cost at
    the reference's own tracing rate."""
    reached = max((s["n_frame"] for r in runs if r["method"] == "guided" for s in r["segments"]), default=0)
    cap_photons = 50 * config.n_frame_max
    cap_s = ref_s * cap_photons / plan.reference_photons if plan.reference_photons else 0.0
    basis = {"sized_by": "largest budget", "largest_budget": max(plan.budgets), "factor": plan.reference_factor,
             "guided_n_frame": reached, "factor_of_guided": plan.reference_photons / reached if reached else None,
             "cap_reference_photons": cap_photons, "cap_reference_s": cap_s, "statement": ""}
    if reached:
        basis["statement"] = (
            f"reference budget: {plan.reference_factor}x the largest budget ({max(plan.budgets):,}) = "
            f"{plan.reference_photons:,} photons a frame; the guided runs, uncapped as loom render runs them "
            f"(n_frame_max {config.n_frame_max:,}), reached N_frame {reached:,}, which the reference holds "
            f"{plan.reference_photons / reached:.1f}x" + (" (under 50x: their error near the noise floor is partly "
                                                         "the reference's)" if plan.reference_photons < 50 * reached
                                                         else "") +
            f"; 50x the cap ({cap_photons:,} a frame) would take about {cap_s / 60:.0f} min at this reference's "
            f"rate ({ref_photons:,} photons in {ref_s:.0f} s)")
    return basis


def _label(r: dict) -> str:
    if r["method"] == "guided":
        n = ", ".join(f"{s['n_frame']:,}" for s in r["segments"])
        f = ", ".join(str(s["fmax"]) for s in r["segments"])
        w = ", ".join(str(s["windows_fmax"]) for s in r["segments"])
        return f"guided d_thr {r['d_thr']:g} (N_frame {n}; F_max {f}; windows {w})"
    if r["method"] == "per-frame":
        return f"per-frame {r['n_photons']:,}"
    return f"{r['method']} {r['n_photons']:,}, F_max {r['fmax']}"
