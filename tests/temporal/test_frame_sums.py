"""pipeline/temporal.FrameSums: a frame's element sums are its batches' sums added in batch order
(one batch: exactly kernels/gather.element_sums_cl of its records), each batch is read once per
process, and a rewritten store never serves stale sums."""
from __future__ import annotations

import shutil
from types import SimpleNamespace

import numpy as np

from kernels.gather import element_sums_cl
from pipeline.store import PhotonStore
from pipeline.temporal import FrameSums
from tests.store.photonstore_helpers import IDENTITY, write_frame
from workers.reconstruct import records_vertex_flux

N_ELEMENTS = 40


def _store(tmp_path, sizes):
    url = str(tmp_path / "p.zarr")
    shutil.rmtree(url, ignore_errors=True)
    PhotonStore.create(url, n_frames=2, n_elements=N_ELEMENTS, frame_numbers=[1, 2], **IDENTITY)
    write_frame(url, 0, sizes, N_ELEMENTS)
    return PhotonStore.open(url, mode="r", **IDENTITY)


def _elements(rng):
    ev = np.stack([rng.choice(30, 3, replace=False) for _ in range(N_ELEMENTS)]).astype(np.int32)
    return SimpleNamespace(element_vertices=ev, n_vertices=30)


def test_frame_sums_add_batches_in_order_and_read_each_once(tmp_path, rng):
    store, elements, cache = _store(tmp_path, [300, 500, 200]), _elements(rng), FrameSums(1 << 24)
    times: dict = {}
    got = cache.get(store, 0, 3, "indirect", 2, elements, direct=True, times=times)
    parts = [store.read_frame(0, batches=[b]) for b in range(3)]
    want = sum((element_sums_cl([r], kind="indirect", split_parity=True)[0] for r in parts[1:]),
               element_sums_cl([parts[0]], kind="indirect", split_parity=True)[0].copy())
    assert got.sums.tobytes() == want.tobytes()
    flux = [records_vertex_flux(r, r.direct, elements.element_vertices, 30) for r in parts]
    assert got.direct_flux.tobytes() == (flux[0] + flux[1] + flux[2]).tobytes()
    assert got.photons_emitted == sum(r.photons_emitted for r in parts)
    # One batch: exactly the element sums of its records; and nothing is read again
    one = cache.get(store, 0, 1, "indirect", 2, elements)
    assert one.sums.tobytes() == element_sums_cl([parts[0]], kind="indirect", split_parity=True)[0].tobytes()
    again: dict = {}
    cache.get(store, 0, 3, "indirect", 2, elements, direct=True, times=again)
    assert "read_s" not in again and "read_s" in times
    # Another kind or parity split is another entry
    assert not np.array_equal(cache.get(store, 0, 1, "all", 1, elements).sums[:, 0],
                              one.sums.sum(axis=1))


def test_a_rewritten_store_is_not_served_stale_sums(tmp_path, rng):
    elements, cache = _elements(rng), FrameSums(1 << 24)
    first = cache.get(_store(tmp_path, [300]), 0, 1, "indirect", 1, elements).sums.copy()
    second = cache.get(_store(tmp_path, [301]), 0, 1, "indirect", 1, elements).sums  # same url, new photons
    assert not np.array_equal(first, second)


def test_the_cache_stays_within_its_bytes(tmp_path, rng):
    store, elements = _store(tmp_path, [100, 100, 100]), _elements(rng)
    one_batch = N_ELEMENTS * 2 * 12 * 8
    cache = FrameSums(2 * one_batch)
    cache.get(store, 0, 3, "indirect", 2, elements)
    assert cache.bytes <= 2 * one_batch and len(cache._entries) == 2
