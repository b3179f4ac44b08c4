"""NaN or Inf in stored records is dropped and counted, never spread into a frame (docs/14-robustness.md §6).

The store refuses such records when they are written, so they can only come from damage or a
foreign writer: here the stored chunks of one batch are rewritten through zarr with NaN, +Inf,
-Inf, a negative energy and an element id the mesh does not have, and the batch's stored sums are
damaged so that the render reads the records (pipeline/collection/batch_sums.py). Reading drops them
(pipeline/store/records.valid_records), counts them (FrameRecords.dropped) and logs a warning; a
render from that store equals, bit for bit, a render from a store whose damaged records carry
zero energy instead (they then add exactly nothing), in every layer of every frame.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
import zarr

from pipeline.config import PhotonConfig
from pipeline.frames.images import EXR_CHANNELS, frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.run.shoot import plan, shoot
from pipeline.scene import read_scene
from pipeline.store import PhotonStore
from tests.stress.scenes import lit_room

FRAMES, N = 3, 20_000
DAMAGED = np.array([3, 57, 901, 2048, 4000])


def _damage(url: str, frame_index: int, values) -> None:
    """Rewrite records DAMAGED of batch 0 of a frame: energy bits from ``values`` (NaN, Inf, ...),
    the last one's element id out of range when ``values`` is not all zero."""
    arr = zarr.open_array(f"{url}/frames/{frame_index}/0", mode="r+")
    rows = arr[...]
    energy = np.asarray(values, np.float32).reshape(-1, 1).repeat(3, axis=1)
    rows[2:5, DAMAGED] = energy.view(np.uint32).T
    if np.any(np.asarray(values) != 0):
        rows[0, DAMAGED[-1]] = (rows[0, DAMAGED[-1]] & ~np.uint32((1 << 30) - 1)) | np.uint32(1 << 29)
    else:
        rows[2:5, DAMAGED[-1]] = 0
    arr[...] = rows
    # The batch's stored sums were made from the undamaged records (pipeline/collection/batch_sums.py): damage
    # them too (a byte of the words that end its batch object), so the render sums the damaged records
    # it keeps. (Damage to the object's header would make the batch not done: the render would trace
    # it again.)
    path = Path(url) / "batch" / f"c.{frame_index}.0"
    data = bytearray(path.read_bytes())
    data[-3] ^= 0x10
    path.write_bytes(bytes(data))


def _run(tmp, name, values):
    scene = lit_room(tmp / "room.glb", frames=FRAMES)
    url = str(tmp / f"{name}.zarr")
    shoot(plan(read_scene(str(scene)), f"1-{FRAMES}", N, PhotonConfig()), url,
          scheduler="synchronous", progress=False, keep_records=True)
    _damage(url, 1, values)
    out = tmp / name
    render(RenderRequest(scene_path=scene, frames=f"1-{FRAMES}", out_dir=out, n_photons=N, store_url=url,
                         keep_records=True, settings=RenderSettings(width=40, height=30, spp=1), temporal="adaptive",
                         fmax=4), scheduler="synchronous")
    return url, [read_exr(frame_paths(out, f)[0])[0] for f in range(1, FRAMES + 1)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bad")
    return (_run(tmp, "damaged", [np.nan, np.inf, -np.inf, -2.0, 1.0]),
            _run(tmp, "zeroed", [0.0, 0.0, 0.0, 0.0, 0.0]))


def test_damaged_records_are_dropped_and_counted(runs, caplog):
    (url, _), (clean_url, _) = runs
    with caplog.at_level(logging.WARNING, logger="pipeline.store.photon_store"):
        records = PhotonStore.open(url).read_frame(1)
    assert records.dropped == len(DAMAGED)
    assert "5 damaged record(s) dropped" in caplog.text
    clean = PhotonStore.open(clean_url).read_frame(1)
    assert clean.dropped == 0 and len(clean) == len(records) + len(DAMAGED)
    assert np.isfinite(records.energy).all()
    assert PhotonStore.open(url).read_frame(0).dropped == 0


def test_damaged_records_never_reach_a_frame(runs):
    (_, damaged), (_, zeroed) = runs
    for frame, ref in zip(damaged, zeroed):
        for name in EXR_CHANNELS:
            assert np.isfinite(frame[name]).all()
            np.testing.assert_array_equal(frame[name], ref[name], err_msg=name)
    assert all((f["indirect.G"] > 0).mean() > 0.99 for f in damaged)
