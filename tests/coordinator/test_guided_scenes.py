"""The guided default (``--photons auto``) on ROOM and ATRIUM against converged per-frame references
(slow: ``make test-all``).

References are one frame's own photons, no temporal collection, ``REFERENCE_PHOTONS`` of them;
their noise floor is stated by comparing their even and odd halves with the same AQM. Frames are
compared as the viewer sees them (pipeline/frames/perceived.py) with the same camera samples and direct
light, so every difference is in the indirect light.
"""
from __future__ import annotations

import numpy as np
import pytest

from kernels.colour import LUMA
from pipeline.collection.maps import MapRequest, WindowSpec, illumination_maps
from pipeline.config import FilterConfig, PhotonConfig, RenderConfig, SegmentConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.frames.perceived import displayed_difference
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.run.shoot import plan, shoot
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore
from pipeline.store.illumination import IlluminationMaps

pytestmark = [pytest.mark.slow, pytest.mark.timeout(3600)]  # minutes of rendering, not a hang
SETTINGS = RenderSettings(width=320, height=240, spp=2)
# 32x the paper's 2,000,000, whose own noise our AQM sees on ROOM; shot in batches of 8,000,000
# (a worker holds one batch's records while it sorts them: about 2 GB)
REFERENCE_PHOTONS = tuple(8_000_000 * i for i in range(1, 9))


class Frames:
    """Composites of one frame of a scene under different indirect maps, same samples and direct light."""

    def __init__(self, scene_path, tmp):
        self.path, self.tmp = scene_path, tmp
        self.scene = read_scene(scene_path)
        self.elements = ElementMesh.build(self.scene)

    def beauty(self, frame: int, irradiance) -> np.ndarray:
        return render_frame(self.scene.pose_frame(frame), self.elements, irradiance,
                            CameraPaths(SETTINGS.width, SETTINGS.height, SETTINGS.spp, seed=0, frame=frame)).beauty

    def reference(self, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """(full, (even, odd)) indirect maps of ``REFERENCE_PHOTONS`` of the frame's own photons."""
        url = str(self.tmp / f"ref-{frame}.zarr")
        for n in REFERENCE_PHOTONS:
            shoot(plan(self.scene, str(frame), n, PhotonConfig(seed=977)), url, scheduler="local", progress=False)
        (lit,) = illumination_maps(PhotonStore.open(url), self.elements, self.scene,
                                   MapRequest(WindowSpec("off", 0), [frame - 1], halves=True))
        return lit.irradiance.mean(axis=0), lit.irradiance

    def compare(self, frame: int, irradiance, adaptation: float) -> dict:
        full, halves = self.reference(frame)
        ref = self.beauty(frame, full)
        floor = displayed_difference(self.beauty(frame, halves[0]), self.beauty(frame, halves[1]), adaptation).d_aqm
        test = self.beauty(frame, irradiance)
        d = displayed_difference(test, ref, adaptation).d_aqm
        y = lambda img: img @ np.asarray(LUMA)  # noqa: E731
        rel = float(np.sqrt(np.mean((y(test) - y(ref)) ** 2)) / np.mean(y(ref)))
        return {"d_aqm": d, "floor_halves": floor, "rel_rms": rel}


def _check_records(records, config: SegmentConfig):
    for r in records:
        print(f"segment {r.index}: frames {r.start}-{r.end} K {r.k} F_max {r.fmax} N_frame {r.n_frame:,} "
              f"d_AQM {r.d_aqm:.2f} % {'(cap)' if r.capped else ''} steps {r.n_frame_steps}")
        assert r.d_aqm <= 100 * config.d_thr or (r.capped and r.n_frame == config.n_frame_max)


def test_room_guided_frames_match_the_converged_reference(tmp_path):
    path = write_builtin("room", tmp_path / "room.glb")
    report = render(RenderRequest(scene_path=path, frames=None, out_dir=tmp_path / "out", settings=SETTINGS))
    from pipeline.segments.records import read_records

    records = read_records(tmp_path / "out")
    _check_records(records, SegmentConfig())
    assert records[0].start == 1 and records[-1].end == 135 and len(report["rendered"]) == 135
    frames = Frames(path, tmp_path)
    maps = IlluminationMaps.open(str(tmp_path / "out" / "photons.zarr"))
    got = {}
    for r in records:
        got[r.k] = frames.compare(r.k, maps.read(r.k - 1), r.frames[str(r.k)]["adaptation"])
        print(f"K {r.k}: guided vs reference d_AQM {got[r.k]['d_aqm']:.2f} % (reference halves "
              f"{got[r.k]['floor_halves']:.2f} %), relative rms {got[r.k]['rel_rms']:.4f}; "
              f"even vs odd at K {r.d_aqm:.2f} %")
    for r in records:
        # The reference's own noise is below what the AQM sees, so it is the truth here
        assert got[r.k]["floor_halves"] < 0.5
        # The paper's claim (§6): d_AQM < 1 % against the reference for d_thr = 3 %; on the
        # defaults 0.03, 0.11 and 0.19 % at K = 23, 68 and 113 (docs/07-segments.md §7)
        assert got[r.k]["d_aqm"] <= 1.0


def test_atrium_guided_frames_lose_the_mottling(tmp_path):
    path = write_builtin("atrium", tmp_path / "atrium.glb")
    frames_spec, k_probe = "136-166", 151
    guided = render(RenderRequest(scene_path=path, frames=frames_spec, out_dir=tmp_path / "guided", settings=SETTINGS))
    old = render(RenderRequest(scene_path=path, frames=frames_spec, out_dir=tmp_path / "old", settings=SETTINGS,
                               n_photons=40_000, fmax=15, temporal="adaptive",
                               config=RenderConfig(filter=FilterConfig(spatial_filter=False))))
    from pipeline.segments.records import read_records

    records = read_records(tmp_path / "guided")
    _check_records(records, SegmentConfig())
    assert sum(v["filtered"] for r in records for v in r.frames.values()) > 0  # Step 5 where windows stay short
    frames = Frames(path, tmp_path)
    rec = next(r for r in records if r.start <= k_probe <= r.end)
    adaptation = rec.frames[str(k_probe)]["adaptation"]
    got = {name: frames.compare(k_probe, IlluminationMaps.open(str(tmp_path / name / "photons.zarr")).read(k_probe - 1),
                                adaptation) for name in ("guided", "old")}
    print({name: {k: round(v, 4) for k, v in g.items()} for name, g in got.items()}, guided["segments"],
          old["segments"])
    # The measure's own spread at this budget: the guided photons' even and odd halves, each against
    # the reference, are two realisations of the same reconstruction (0.5 points apart here)
    store = PhotonStore.open(str(tmp_path / "guided" / "photons.zarr"))
    (halves,) = illumination_maps(store, frames.elements, frames.scene,
                                  MapRequest(WindowSpec(rec.temporal, rec.fmax), [k_probe - 1], halves=True),
                                  filter=FilterConfig())
    spread = abs(frames.compare(k_probe, halves.irradiance[0], adaptation)["d_aqm"]
                 - frames.compare(k_probe, halves.irradiance[1], adaptation)["d_aqm"])
    print(f"ATRIUM K {k_probe}: guided {got['guided']['d_aqm']:.2f} %, reference halves "
          f"{got['guided']['floor_halves']:.2f} %, spread of the measure {spread:.2f} points")
    # 40,000 photons a frame at F_max 15 without the filter show mottled indirect light at a
    # glance; the guided frames do not: they are as close to the reference as the reference's own
    # halves are to each other (its noise floor), within the measure's spread (docs/07-segments.md §7)
    assert got["old"]["d_aqm"] > 10.0
    assert got["guided"]["d_aqm"] <= max(3.0, got["guided"]["floor_halves"] + spread)
    assert got["guided"]["rel_rms"] < 0.5 * got["old"]["rel_rms"]
