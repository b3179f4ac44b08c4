"""pipeline/batch_sums: a batch's sums (indirect element sums split by parity, direct vertex flux)
are stored sparse by its writer and read instead of its records, with the bits of summing the
records; a frame's sums are its batches' sums added in batch order; each batch is read once per
process; a rewritten store never serves stale sums; a damaged summary falls back to the records
where they are kept and is refused in one line where they are not."""
from __future__ import annotations

import logging
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from kernels.gather import corners_to_vertices, element_sums_cl
from pipeline.collection.batch_sums import HEADER, SLOTS, FrameSums, batch_summary, decode, encode, summariser
from pipeline.collection.estimators import records_vertex_flux
from pipeline.errors import LoomError
from pipeline.store import ELEMENT_MASK, FrameRecords, PhotonStore
from tests.store.photonstore_helpers import IDENTITY, make_batch, write_frame

N_ELEMENTS, N_VERTICES = 40, 30
NO_RECORDS = dict(IDENTITY, keep_records=False)


def _elements(seed=3, n_elements=N_ELEMENTS):
    rng = np.random.default_rng(seed)
    ev = np.stack([rng.choice(N_VERTICES, 3, replace=False) for _ in range(n_elements)]).astype(np.int32)
    return SimpleNamespace(element_vertices=ev, n_vertices=N_VERTICES, n_elements=n_elements)


def _float64_summary(records):
    """A batch's sums (E, 2, 3, 4) and direct flux (V, 3) in float64, before the store's rounding."""
    return (element_sums_cl([records], kind="indirect", split_parity=True)[0],
            corners_to_vertices(element_sums_cl([records], kind="direct")[0, :, 0, :, :3],
                                _elements().element_vertices, N_VERTICES))


def _store(tmp_path, sizes, *, keep_records=True, name="p.zarr", elements=N_ELEMENTS):
    """A store with one frame of batches ``sizes``, each with the shoot task's summary; with the
    raw records or without."""
    url = str(tmp_path / name)
    shutil.rmtree(url, ignore_errors=True)
    identity = IDENTITY if keep_records else NO_RECORDS
    PhotonStore.create(url, n_frames=2, n_elements=elements, frame_numbers=[1, 2], **identity)
    store = PhotonStore.open(url, mode="r+", **identity)
    start = 0
    for b, n in enumerate(sizes):
        batch = make_batch(0, b, n, elements, photon_start=start)
        store.write_batch(0, b, batch, summarise=summariser(_elements(n_elements=elements)))
        start += batch.photons_emitted
    return PhotonStore.open(url, mode="r", **identity)


def _grouped(batch, n_elements=N_ELEMENTS):
    """A batch's records as the shoot task sums them: grouped by element, the writer's order kept
    within an element (a stable argsort here, a radix sort in the store)."""
    key, bary, energy = (np.asarray(getattr(batch, k)) for k in ("key", "bary", "energy"))
    order = np.argsort(key & np.uint32(ELEMENT_MASK), kind="stable")
    offsets = np.zeros(n_elements + 1, np.int64)
    np.cumsum(np.bincount(key & np.uint32(ELEMENT_MASK), minlength=n_elements), out=offsets[1:])
    return FrameRecords.merge(0, 0, (0,), [(key[order], bary[order], energy[order].astype(np.float32), offsets)],
                              n_elements, 1)


def _want(sizes, n_parity):
    """The frame's sums from its batches ``sizes`` (tests/store/photonstore_helpers.make_batch),
    summed the documented way: each batch's float64 sums over its records grouped by element,
    rounded as stored (float32, sqrt(Q)), then added in float64 in batch order."""
    parts, start = [], 0
    for b, n in enumerate(sizes):
        batch = make_batch(0, b, n, N_ELEMENTS, photon_start=start)
        parts.append(_grouped(batch))
        start += batch.photons_emitted
    split, flux = [], []
    for r in parts:
        sums, f = _float64_summary(r)
        stored = sums.copy()
        stored[..., 3] = np.sqrt(stored[..., 3])
        stored = stored.astype(np.float32).astype(np.float64)
        stored[..., 3] *= stored[..., 3]
        split.append(stored)
        flux.append(f.astype(np.float32).astype(np.float64))
    sums = [s if n_parity == 2 else s[:, :1] + s[:, 1:] for s in split]
    total = sums[0].copy()
    for s in sums[1:]:
        total += s
    total_flux = flux[0].copy()
    for f in flux[1:]:
        total_flux += f
    return total, total_flux


@pytest.mark.parametrize("keep_records", [False, True], ids=["sums only", "with records"])
@pytest.mark.parametrize("n_parity", [1, 2])
def test_frame_sums_add_batches_in_order_with_the_records_bits(tmp_path, keep_records, n_parity):
    store, cache = _store(tmp_path, [700, 900, 500], keep_records=keep_records), FrameSums(1 << 24)
    times: dict = {}
    got = cache.get(store, 0, 3, "indirect", n_parity, _elements(), times=times)
    sums, flux = _want([700, 900, 500], n_parity)
    assert got.sums.shape == (N_ELEMENTS, n_parity, 3, 4)
    assert got.sums.tobytes() == sums.tobytes()
    assert got.direct_flux.tobytes() == flux.tobytes()
    assert got.photons_emitted == store.photons_emitted(0)
    # stored summaries are read, never summed again
    assert "frame_sums_s" not in times and "read_s" in times
    again: dict = {}
    cache.get(store, 0, 3, "indirect", 3 - n_parity, _elements(), times=again)
    assert again == {}  # the other parity split comes from the same entries


def test_the_direct_flux_is_the_per_record_sum(tmp_path):
    """The direct element sums scattered to the vertices equal pipeline/collection/estimators' per-record sum
    to rounding."""
    records = _store(tmp_path, [900]).read_frame(0, batches=[0])
    ev = _elements().element_vertices
    got = corners_to_vertices(element_sums_cl([records], kind="direct")[0, :, 0, :, :3], ev, N_VERTICES)
    want = records_vertex_flux(records, records.direct, ev, N_VERTICES)
    assert want.max() > 0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * want.max())


def test_the_stored_summary_is_the_records_summary(tmp_path):
    store = _store(tmp_path, [700])
    stored = store.read_summary(0, 0)
    assert stored.tobytes() == batch_summary(_grouped(make_batch(0, 0, 700, N_ELEMENTS)), _elements()).tobytes()
    # from the kept records (total order within an element): the same to float32 rounding
    again = decode(batch_summary(store.read_frame(0, batches=[0]), _elements()), _elements())
    for a, b in zip(again, decode(stored, _elements())):
        np.testing.assert_allclose(a, b, rtol=3e-7, atol=0)
    assert _store(tmp_path, [700], keep_records=False, name="bare.zarr").read_summary(0, 0).tobytes() == \
        stored.tobytes()


def test_a_store_without_records_writes_none_and_refuses_to_read_them(tmp_path):
    store = _store(tmp_path, [700, 300], keep_records=False)
    assert not (Path(store.url) / "frames").exists() or not any((Path(store.url) / "frames").rglob("c.*"))
    assert store.verify_batch(0, 0) and store.verify_batch(0, 1)
    with pytest.raises(LoomError, match="holds no hit records.*--keep-records"):
        store.read_frame(0)
    with pytest.raises(LoomError, match="holds no hit records"):
        FrameSums(1 << 24).get(store, 0, 1, "all", 1, _elements())  # other kinds need the records
    # a writer without a summary is a caller's bug there: the sums are all the store keeps
    writer = PhotonStore.open(store.url, mode="r+")
    with pytest.raises(ValueError, match="needs the batch's summary"):
        writer.write_batch(0, 2, make_batch(0, 2, 100, N_ELEMENTS, photon_start=writer.photons_emitted(0)))


def test_sparse_sums_hold_only_what_a_batch_hit():
    """A batch on 2 of 40 elements stores 2 rows and their ids; decode gives the dense sums back,
    zeros elsewhere, to the bit (Q through its square root)."""
    rng = np.random.default_rng(4)
    sums = np.zeros((N_ELEMENTS, 2, 3, 4))
    sums[[3, 17]] = rng.random((2, 2, 3, 4))
    flux = np.zeros((N_VERTICES, 3))
    flux[[0, 5, 29]] = rng.random((3, 3))
    words = encode(sums, flux)
    assert words.dtype == np.uint32 and words.size == HEADER + 2 * (1 + SLOTS) + 3 * 4
    got_sums, got_flux = decode(words, _elements())
    stored = sums.copy()
    stored[..., 3] = np.sqrt(stored[..., 3])
    stored = stored.astype(np.float32).astype(np.float64)
    stored[..., 3] *= stored[..., 3]
    assert got_sums.tobytes() == stored.tobytes()
    assert got_flux.tobytes() == flux.astype(np.float32).astype(np.float64).tobytes()
    other = SimpleNamespace(element_vertices=None, n_vertices=N_VERTICES, n_elements=N_ELEMENTS + 1)
    with pytest.raises(ValueError, match="the mesh has"):
        decode(words, other)
    with pytest.raises(ValueError, match="does not hold"):
        decode(words[:-1], _elements())


def test_a_small_batch_on_a_fine_mesh_stores_fewer_bytes_than_dense_sums(tmp_path):
    """4,000 elements, 300 records: the sparse sums take a fraction of the dense 4,000 x 24 floats."""
    store = _store(tmp_path, [300], keep_records=False, elements=4000)
    size = _summary_file(store).stat().st_size  # the whole batch object: header, counts and sums
    assert size < 4000 * SLOTS * 4 / 10


def _summary_file(store) -> Path:
    return Path(store.url) / "batch" / "c.0.0"


@pytest.mark.parametrize("damage", ["flipped", "truncated"])
@pytest.mark.parametrize("keep_records", [True, False], ids=["with records", "sums only"])
def test_a_damaged_summary_falls_back_to_the_records_or_is_refused(tmp_path, damage, keep_records, caplog):
    """The batch object's header is whole (the batch is done) but its summary words are not: a
    damaged header makes the batch not done instead (tests/store/test_photon_store.py)."""
    store = _store(tmp_path, [800], keep_records=keep_records)
    path = _summary_file(store)
    data = bytearray(path.read_bytes())
    if damage == "flipped":  # a bit of the compressed words: their CRC-32 no longer matches
        data[-3] ^= 0x10
    else:
        data = data[:len(data) // 2]
    path.write_bytes(bytes(data))
    assert store.is_done(0, 0)
    with caplog.at_level(logging.WARNING, logger="pipeline.store.photon_store"):
        assert store.read_summary(0, 0) is None
    assert "damaged batch summary ignored" in caplog.text
    assert not store.verify_batch(0, 0)
    times: dict = {}
    if not keep_records:
        with pytest.raises(LoomError, match="batch sums missing or damaged and no hit records kept"):
            FrameSums(1 << 24).get(store, 0, 1, "indirect", 2, _elements(), times=times)
        return
    got = FrameSums(1 << 24).get(store, 0, 1, "indirect", 2, _elements(), times=times)
    assert "frame_sums_s" in times and np.isfinite(got.sums).all()
    # the kept records are in the total order, not the tracer's: the same sums to float32 rounding
    np.testing.assert_allclose(got.sums, _want([800], 2)[0], rtol=3e-7, atol=0)


def test_other_kinds_are_summed_from_the_records(tmp_path):
    store = _store(tmp_path, [600])
    got = FrameSums(1 << 24).get(store, 0, 1, "all", 1, _elements())
    split = element_sums_cl([store.read_frame(0, batches=[0])], kind="all", split_parity=True)[0]
    assert got.sums.tobytes() == (split[:, :1] + split[:, 1:]).tobytes() and got.direct_flux is None


def test_a_rewritten_store_is_not_served_stale_sums(tmp_path):
    cache = FrameSums(1 << 24)
    first = cache.get(_store(tmp_path, [700]), 0, 1, "indirect", 1, _elements()).sums.copy()
    second = cache.get(_store(tmp_path, [701]), 0, 1, "indirect", 1, _elements()).sums
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
    words = encode(sums, flux)
    assert np.isfinite(words.view(np.float32)).all()
    got_sums, got_flux = decode(words, el)
    np.testing.assert_allclose(got_sums, sums, rtol=2.5e-7, atol=0)
    np.testing.assert_allclose(got_flux, flux, rtol=1.2e-7, atol=0)
