"""pipeline/batch_sums: a batch's sums (indirect element sums split by parity, direct vertex flux)
are stored by its writer and read instead of its records, with the bits of summing the records;
a frame's sums are its batches' sums added in batch order; each batch is read once per process;
a rewritten store never serves stale sums; a missing, foreign or damaged summary falls back to
the records."""
from __future__ import annotations

import logging
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from kernels.gather import corners_to_vertices, element_sums_cl
from pipeline.batch_sums import FrameSums, batch_summary, stored_form, summariser, working_form
from pipeline.store import PhotonStore
from tests.store.photonstore_helpers import IDENTITY, make_batch, write_frame
from workers.reconstruct import records_vertex_flux

N_ELEMENTS, N_VERTICES = 40, 30


def _elements(seed=3):
    rng = np.random.default_rng(seed)
    ev = np.stack([rng.choice(N_VERTICES, 3, replace=False) for _ in range(N_ELEMENTS)]).astype(np.int32)
    return SimpleNamespace(element_vertices=ev, n_vertices=N_VERTICES, n_elements=N_ELEMENTS)


def _float64_summary(records):
    """A batch's summary as float64 values, before the store's rounding (older stores hold these)."""
    return np.concatenate([element_sums_cl([records], kind="indirect", split_parity=True)[0].reshape(-1),
                           corners_to_vertices(element_sums_cl([records], kind="direct")[0, :, 0, :, :3],
                                               _elements().element_vertices, N_VERTICES).reshape(-1)])


def _store(tmp_path, sizes, *, summarise=False, name="p.zarr"):
    """A store with one frame of batches ``sizes``, written with or without batch summaries
    (``summarise`` True: the shoot task's summariser; a function: that one)."""
    url = str(tmp_path / name)
    shutil.rmtree(url, ignore_errors=True)
    PhotonStore.create(url, n_frames=2, n_elements=N_ELEMENTS, frame_numbers=[1, 2], **IDENTITY)
    store = PhotonStore.open(url, mode="r+", **IDENTITY)
    start = 0
    for b, n in enumerate(sizes):
        batch = make_batch(0, b, n, N_ELEMENTS, photon_start=start)
        how = summarise if callable(summarise) else summariser(_elements()) if summarise else None
        store.write_batch(0, b, **batch, summarise=how)
        start += batch["photons_emitted"]
    return PhotonStore.open(url, mode="r", **IDENTITY)


def _want(store, n_batches, n_parity):
    """The frame's sums from its records, summed the documented way: each batch's float64 sums
    rounded as stored (float32, sqrt(Q)), then added in float64 in batch order."""
    parts = [store.read_frame(0, batches=[b]) for b in range(n_batches)]
    split, flux = [], []
    for r in parts:
        sums, f = working_form(stored_form(_float64_summary(r), _elements()), _elements())
        split.append(sums)
        flux.append(f)
    sums = [s if n_parity == 2 else s[:, :1] + s[:, 1:] for s in split]
    total = sums[0].copy()
    for s in sums[1:]:
        total += s
    total_flux = flux[0].copy()
    for f in flux[1:]:
        total_flux += f
    return total, total_flux


@pytest.mark.parametrize("stored", [False, True], ids=["from records", "stored"])
@pytest.mark.parametrize("n_parity", [1, 2])
def test_frame_sums_add_batches_in_order_with_the_records_bits(tmp_path, stored, n_parity):
    store, cache = _store(tmp_path, [700, 900, 500], summarise=stored), FrameSums(1 << 24)
    times: dict = {}
    got = cache.get(store, 0, 3, "indirect", n_parity, _elements(), times=times)
    sums, flux = _want(store, 3, n_parity)
    assert got.sums.shape == (N_ELEMENTS, n_parity, 3, 4)
    assert got.sums.tobytes() == sums.tobytes()
    assert got.direct_flux.tobytes() == flux.tobytes()
    assert got.photons_emitted == store.photons_emitted(0)
    # stored summaries are read, never summed again; without them the records are summed once
    assert ("frame_sums_s" in times) != stored and "read_s" in times
    again: dict = {}
    cache.get(store, 0, 3, "indirect", 3 - n_parity, _elements(), times=again)
    assert again == {}  # the other parity split comes from the same entries


def test_the_direct_flux_is_the_per_record_sum(tmp_path):
    """The direct element sums scattered to the vertices equal workers/reconstruct's per-record sum to rounding."""
    records = _store(tmp_path, [900]).read_frame(0, batches=[0])
    ev = _elements().element_vertices
    got = corners_to_vertices(element_sums_cl([records], kind="direct")[0, :, 0, :, :3], ev, N_VERTICES)
    want = records_vertex_flux(records, records.direct, ev, N_VERTICES)
    assert want.max() > 0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * want.max())


def test_the_stored_summary_is_the_records_summary(tmp_path):
    store = _store(tmp_path, [700], summarise=True)
    stored = store.read_summary(0, 0)
    assert stored.tobytes() == batch_summary(store.read_frame(0, batches=[0]), _elements()).tobytes()
    assert _store(tmp_path, [700], name="bare.zarr").read_summary(0, 0) is None


def _summary_file(store) -> Path:
    return Path(store.url) / "summaries" / "c.0.0"


@pytest.mark.parametrize("damage", ["nan", "truncated", "foreign"])
def test_a_damaged_or_foreign_summary_falls_back_to_the_records(tmp_path, damage, caplog):
    store = _store(tmp_path, [800], summarise=True)
    path = _summary_file(store)
    data = bytearray(path.read_bytes())
    if damage == "nan":  # a summary whose values decode to NaN
        import numcodecs.blosc as blosc

        head = 8 + 16
        values = np.frombuffer(blosc.decompress(bytes(data[head:])), "<f4").copy()
        values[5] = np.nan
        data[head:] = blosc.compress(values.tobytes(), b"lz4", 5, blosc.SHUFFLE, 0, 4)
    elif damage == "truncated":
        data = data[:len(data) // 2]
    else:  # another batch's summary: the digest in its header does not match
        data[8] ^= 0xFF
    path.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="pipeline.store.photon_store"):
        assert store.read_summary(0, 0) is None
    assert "damaged or foreign batch summary ignored" in caplog.text
    times: dict = {}
    got = FrameSums(1 << 24).get(store, 0, 1, "indirect", 2, _elements(), times=times)
    assert "frame_sums_s" in times and np.isfinite(got.sums).all()
    assert got.sums.tobytes() == _want(store, 1, 2)[0].tobytes()


def test_a_summary_larger_than_its_records_is_not_stored(tmp_path):
    """40 elements and 30 vertices: 4,200 bytes of float32 sums, stored for 210 records (4,200 bytes) and more."""
    store = _store(tmp_path, [209, 210], summarise=True)
    assert store.read_summary(0, 0) is None and store.read_summary(0, 1) is not None
    sums, flux = _want(store, 2, 2)
    got = FrameSums(1 << 24).get(store, 0, 2, "indirect", 2, _elements())
    assert got.sums.tobytes() == sums.tobytes() and got.direct_flux.tobytes() == flux.tobytes()


def test_other_kinds_are_summed_from_the_records(tmp_path):
    store = _store(tmp_path, [600], summarise=True)
    got = FrameSums(1 << 24).get(store, 0, 1, "all", 1, _elements())
    split = element_sums_cl([store.read_frame(0, batches=[0])], kind="all", split_parity=True)[0]
    assert got.sums.tobytes() == (split[:, :1] + split[:, 1:]).tobytes() and got.direct_flux is None


def test_a_rewritten_store_is_not_served_stale_sums(tmp_path):
    cache = FrameSums(1 << 24)
    first = cache.get(_store(tmp_path, [700], summarise=True), 0, 1, "indirect", 1, _elements()).sums.copy()
    second = cache.get(_store(tmp_path, [701], summarise=True), 0, 1, "indirect", 1, _elements()).sums
    assert not np.array_equal(first, second)  # same url, new photons


def test_the_cache_stays_within_its_bytes(tmp_path):
    store = _store(tmp_path, [100, 100, 100])
    one_batch = N_ELEMENTS * 2 * 12 * 8 + N_VERTICES * 3 * 8
    cache = FrameSums(2 * one_batch)
    cache.get(store, 0, 3, "indirect", 2, _elements())
    assert cache.bytes <= 2 * one_batch and len(cache._entries) == 2


def test_write_frame_helper_still_writes_plain_batches(tmp_path):
    url = str(tmp_path / "h.zarr")
    PhotonStore.create(url, n_frames=1, n_elements=N_ELEMENTS, frame_numbers=[1], **IDENTITY)
    write_frame(url, 0, [50], N_ELEMENTS)
    assert PhotonStore.open(url, **IDENTITY).read_summary(0, 0) is None


@pytest.mark.parametrize("scale", [1e-30, 1.0, 1e30])
def test_the_stored_form_keeps_sums_and_q_to_float32_rounding_at_any_brightness(scale):
    """float32 with sqrt(Q): every value within float32's rounding of the float64 one, Q too,
    where Q itself (1e60 for energies of 1e30) would overflow float32."""
    el = _elements()
    rng = np.random.default_rng(9)
    rgb = rng.random((N_ELEMENTS, 2, 3, 3)) * scale
    sums = np.concatenate([rgb, (rgb.sum(axis=-1, keepdims=True) * scale) * 0.3], axis=-1)  # Q ~ energy^2
    flux = rng.random((N_VERTICES, 3)) * scale
    stored = stored_form(np.concatenate([sums.reshape(-1), flux.reshape(-1)]), el)
    assert stored.dtype == np.float32 and np.isfinite(stored).all()
    got_sums, got_flux = working_form(stored, el)
    np.testing.assert_allclose(got_sums, sums, rtol=2.5e-7, atol=0)
    np.testing.assert_allclose(got_flux, flux, rtol=1.2e-7, atol=0)
    # A float64 summary of an older store is rounded the same way on reading
    old = np.concatenate([sums.reshape(-1), flux.reshape(-1)])
    assert all(a.tobytes() == b.tobytes() for a, b in zip(working_form(old, el), (got_sums, got_flux)))


def test_a_float64_summary_of_an_older_store_reads_as_a_float32_one(tmp_path):
    """Stores written before float32 summaries hold float64 ones ("LOOMSUM1"): read, rounded as
    new ones are, and the frame's sums carry the same bits as from a new store."""
    new = _store(tmp_path, [700, 900], summarise=True, name="new.zarr")
    old = _store(tmp_path, [700, 900], summarise=_float64_summary, name="old.zarr")
    el = _elements()
    assert _summary_file(old).read_bytes()[:8] == b"LOOMSUM1"
    assert old.read_summary(0, 0).dtype == np.float64
    times: dict = {}
    got_old = FrameSums(1 << 24).get(old, 0, 2, "indirect", 2, el, times=times)
    got_new = FrameSums(1 << 24).get(new, 0, 2, "indirect", 2, el)
    assert "frame_sums_s" not in times  # read, not summed again
    assert got_old.sums.tobytes() == got_new.sums.tobytes()
    assert got_old.direct_flux.tobytes() == got_new.direct_flux.tobytes()
