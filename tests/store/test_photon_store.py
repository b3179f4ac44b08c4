"""The photon store on real zarr directories: layout, round trips, idempotence, refusals."""
from __future__ import annotations

import json
import pickle
import time
from dataclasses import asdict, replace

import numpy as np
import pytest
import zarr
from photonstore_helpers import IDENTITY, MADE_BY, contents, make_batch, snapshot, write_frame

from pipeline.errors import LoomError
from pipeline.photons.tracing import PhotonBatch
from pipeline.store import (
    CATEGORIES,
    ELEMENT_MASK,
    RECORD_BYTES,
    FrameRecords,
    PhotonStore,
    counting_io,
    pack_key,
    sort_records,
)
from pipeline.store.records import category_counts

N_ELEMENTS = 500


def create(url, n_frames=4, n_elements=N_ELEMENTS, **overrides) -> PhotonStore:
    """A store of the test identity, but for ``overrides`` (of its identity's fields too)."""
    made_by = {k: overrides.pop(k) for k in asdict(MADE_BY) if k in overrides}
    args = dict(IDENTITY, n_frames=n_frames, n_elements=n_elements,
                frame_numbers=list(range(101, 101 + n_frames)), max_batches=4)
    args.update(overrides, identity=replace(MADE_BY, **made_by))
    return PhotonStore.create(url, **args)


@pytest.fixture
def store(tmp_path) -> PhotonStore:
    return create(tmp_path / "run.zarr")


def expected_sorted(batch: dict):
    order = sort_records(batch.key, batch.bary, batch.energy)
    return batch.key[order], batch.bary[order], batch.energy[order]


def check_consistent(records: FrameRecords, n_elements: int) -> None:
    """Sorted by element, offsets delimit each element, derived fields agree with the key."""
    assert np.all(np.diff(records.element.astype(np.int64)) >= 0)
    assert records.offsets[0] == 0 and records.offsets[-1] == len(records)
    per_element = np.bincount(records.element, minlength=n_elements)
    np.testing.assert_array_equal(np.diff(records.offsets), per_element)
    np.testing.assert_array_equal(records.element, records.key & ELEMENT_MASK)
    np.testing.assert_array_equal(records.direct, records.key >> 31 == 1)
    np.testing.assert_array_equal(records.parity, (records.key >> 30) & 1)


def test01_record_is_20_bytes_and_described(store):
    assert RECORD_BYTES == 20
    attrs = dict(zarr.open_group(store.url, mode="r").attrs)
    assert attrs["record_layout"]["record_bytes"] == 20
    assert attrs["format_version"] == 5 and attrs["frame_numbers"] == [101, 102, 103, 104]
    assert {k: attrs[k] for k in asdict(MADE_BY)} == asdict(MADE_BY) and attrs["keep_records"] is True


@pytest.mark.parametrize("n", [0, 1, 20_000])
def test02_round_trip(store, n):
    batch = make_batch(1, 0, n, N_ELEMENTS)
    assert store.write_batch(1, 0, batch) is True
    assert store.is_done(1, 0) and not store.is_done(1, 1) and store.done_batches(1) == [0]
    got = store.read_frame(1)
    key, bary, energy = expected_sorted(batch)
    np.testing.assert_array_equal(got.key, key)
    np.testing.assert_array_equal(np.stack([got.b1, got.b2], axis=1), bary)
    np.testing.assert_array_equal(got.energy, energy)
    check_consistent(got, N_ELEMENTS)
    assert got.photons_emitted == store.photons_emitted(1) == batch.photons_emitted
    np.testing.assert_array_equal(store.counts(frames=[1])[0], np.diff(got.offsets))
    assert store.counts(frames=[0]).sum() == 0 and store.done_batches(0) == []


def test03_merged_batches(store):
    batches = write_frame(store.url, 2, [3000, 3000, 6000], N_ELEMENTS)
    got = store.read_frame(2)
    check_consistent(got, N_ELEMENTS)
    assert got.batches == (0, 1, 2) and len(got) == 12000
    assert got.photons_emitted == sum(b.photons_emitted for b in batches.values())
    # Within an element, batch 0's records come first, then batch 1's, then batch 2's
    parts = [store.read_frame(2, batches=[b]) for b in range(3)]
    for e in (0, 1, 7, N_ELEMENTS - 1):
        lo, hi = got.offsets[e], got.offsets[e + 1]
        expect = np.concatenate([p.key[p.offsets[e]:p.offsets[e + 1]] for p in parts])
        np.testing.assert_array_equal(got.key[lo:hi], expect)
    sub = store.read_frame(2, batches=[0, 2])
    assert len(sub) == 9000 and sub.photons_emitted == batches[0].photons_emitted * 3
    np.testing.assert_array_equal(store.counts(frames=[2])[0], np.diff(got.offsets))


def test04_input_order_does_not_matter(tmp_path):
    batch = make_batch(0, 0, 5000, 50)  # 100 hits per element: many equal (element, key) pairs
    batch.bary[::3] = 0  # and many records equal but for their energy
    flipped = replace(batch, key=batch.key[::-1].copy(), bary=batch.bary[::-1].copy(),
                      energy=batch.energy[::-1].copy())
    a, b = create(tmp_path / "a", n_elements=50), create(tmp_path / "b", n_elements=50)
    a.write_batch(0, 0, batch)
    b.write_batch(0, 0, flipped)
    assert contents(tmp_path / "a") == contents(tmp_path / "b")


def test05_rewrite_is_idempotent_and_refuses_other_photons(store, tmp_path):
    batch = make_batch(0, 0, 4000, N_ELEMENTS)
    store.write_batch(0, 0, batch)
    before = snapshot(tmp_path / "run.zarr")
    assert store.write_batch(0, 0, batch) is False
    assert snapshot(tmp_path / "run.zarr") == before  # not even rewritten: same inode and mtime
    other = replace(batch, energy=batch.energy * np.float32(2))
    with pytest.raises(LoomError, match="already done with different photons"):
        store.write_batch(0, 0, other)
    assert snapshot(tmp_path / "run.zarr") == before


def test06_append_leaves_earlier_batches_untouched(store, tmp_path):
    write_frame(store.url, 0, [3000], N_ELEMENTS)
    write_frame(store.url, 1, [3000], N_ELEMENTS)
    before = snapshot(tmp_path / "run.zarr")
    b1 = make_batch(0, 1, 6000, N_ELEMENTS, photon_start=1500)
    store.write_batch(0, 1, b1)
    after = snapshot(tmp_path / "run.zarr")
    assert {k: after[k] for k in before} == before  # same bytes, inode and mtime
    new = sorted(set(after) - set(before))
    assert new and all(k.startswith(("frames/0/1/", "batch/c.0.1")) for k in new)
    assert store.done_batches(0) == [0, 1] and store.photons_emitted(0) == 1500 + 3000


def test07_crash_before_done_marker(tmp_path):
    """Records and counts written but no done marker: not done, invisible, completed by a rerun."""
    crashed, clean = create(tmp_path / "crashed"), create(tmp_path / "clean")
    batches = write_frame(crashed.url, 3, [2000], N_ELEMENTS)
    write_frame(clean.url, 3, [2000, 2000], N_ELEMENTS)
    second = make_batch(3, 1, 2000, N_ELEMENTS, photon_start=1000)
    assert (second.photons_emitted, second.photon_start) == (1000, 1000)
    crashed._write_payload(crashed._prepare(3, 1, second, None))
    assert (tmp_path / "crashed/frames/3/1/c.0.0").exists()
    assert not crashed.is_done(3, 1) and crashed.done_batches(3) == [0]
    assert len(crashed.read_frame(3)) == 2000 and crashed.photons_emitted(3) == 1000
    np.testing.assert_array_equal(crashed.counts(frames=[3])[0],
                                  np.bincount(batches[0].key & ELEMENT_MASK,
                                              minlength=N_ELEMENTS))
    with pytest.raises(LoomError, match="batch 1 is not done"):
        crashed.write_batch(3, 2, make_batch(3, 2, 10, N_ELEMENTS, photon_start=2000))
    assert crashed.write_batch(3, 1, second) is True
    assert contents(tmp_path / "crashed") == contents(tmp_path / "clean")


@pytest.mark.parametrize("scheme", ["file", "memory", "path"])
def test08_urls(tmp_path, scheme):
    url = {"file": (tmp_path / "u.zarr").as_uri(), "path": str(tmp_path / "u.zarr"),
           "memory": f"memory://photonloom-test/{tmp_path.name}"}[scheme]
    create(url)
    write_frame(url, 1, [500, 500], N_ELEMENTS)
    reopened = PhotonStore.open(url, **IDENTITY)
    assert reopened.done_batches(1) == [0, 1] and len(reopened.read_frame(1)) == 1000
    check_consistent(reopened.read_frame(1), N_ELEMENTS)
    if scheme != "memory":
        assert (tmp_path / "u.zarr/frames/1/1/zarr.json").exists()


@pytest.mark.parametrize("attr, value", [("scene_hash", "scene-other"), ("config_hash", "cfg-9"),
                                         ("seed", 8), ("n_elements", 501),
                                         ("frame_numbers", [1, 2, 3, 4])])
def test09_create_refuses_another_run(store, attr, value):
    write_frame(store.url, 0, [100], N_ELEMENTS)
    with pytest.raises(LoomError) as err:
        create(store.url, **{attr: value})
    message = str(err.value)
    assert "\n" not in message and store.url in message and attr in message
    assert create(store.url).done_batches(0) == [0]  # same identity: resumes


@pytest.mark.parametrize("attr, value", [("scene_hash", "x"), ("config_hash", "y"), ("seed", 0)])
def test10_open_refuses_another_run(store, attr, value):
    with pytest.raises(LoomError, match=f"{attr}: store was made with {attr}="):
        PhotonStore.open(store.url, identity=replace(MADE_BY, **{attr: value}))
    assert PhotonStore.open(store.url, **IDENTITY).n_elements == N_ELEMENTS


def test11_not_a_photon_store(tmp_path):
    (tmp_path / "plain").mkdir()
    (tmp_path / "plain/notes.txt").write_text("hello")
    zarr.create_array(tmp_path / "array", shape=(3,), dtype="u1")
    zarr.create_group(tmp_path / "group", attributes={"x": 1})
    old = create(tmp_path / "old")
    zarr.open_group(old.url, mode="r+").attrs.update({"format_version": 0})
    cases = {"missing": "no photon store here", "plain": "not a zarr group",
             "array": "is a zarr array", "group": "not a photon store",
             "old": "format version 0"}
    for name, message in cases.items():
        with pytest.raises(LoomError, match=message):
            PhotonStore.open(tmp_path / name)
    assert not (tmp_path / "missing").exists()
    for name in ("plain", "array", "group", "old"):
        with pytest.raises(LoomError):
            create(tmp_path / name)
    assert (tmp_path / "plain/notes.txt").read_text() == "hello"


def test12_interrupted_create_is_finished_by_create(tmp_path):
    store = create(tmp_path / "s")
    zarr.open_group(store.url, mode="r+").attrs.update({"complete": False})
    with pytest.raises(LoomError, match="creation was interrupted"):
        PhotonStore.open(store.url)
    create(store.url)
    assert PhotonStore.open(store.url).counts().shape == (4, N_ELEMENTS)


def test13_unwritable_path(tmp_path):
    (tmp_path / "afile").write_text("")  # works as root too, unlike chmod
    with pytest.raises(LoomError, match="cannot create photon store") as err:
        create(tmp_path / "afile/run.zarr")
    assert "\n" not in str(err.value)


def _bad(frame_index=0, batch=0, **changes):
    return frame_index, batch, replace(make_batch(0, 0, 50, N_ELEMENTS), **changes)


@pytest.mark.parametrize("args, message", [
    (_bad(frame_index=-1), "frame_index -1 is out of range"),
    (_bad(frame_index=4), r"frame_index 4 is out of range \(must be in \[0, 4\)\)"),
    (_bad(batch=4), "batch 4 is out of range"),
    (_bad(batch=1.0), "batch must be an integer"),
    (_bad(bary=np.zeros((49, 2), np.uint16)), "differ in length: key 50, bary 49, energy 50"),
    (_bad(bary=np.zeros((50, 3), np.uint16)), r"bary has shape \(50, 3\), expected \(n, 2\)"),
    (_bad(bary=np.full((50, 2), 0.5)), "bary must be integers"),
    (_bad(key=np.full(50, N_ELEMENTS, np.uint32)), "element id 500 >= n_elements 500"),
    (_bad(key=np.full(50, -1)), "key has values outside uint32"),
    (_bad(energy=np.full((50, 3), np.nan)), "energy must be finite and >= 0"),
    (_bad(energy=np.full((50, 3), -1.0)), "energy must be finite and >= 0"),
    (_bad(photon_start=25), "photon_start 25 is not contiguous: the previous batch ends at 0"),
    (_bad(photons_emitted=0), "photons_emitted 0 is out of range"),
    (_bad(batch=1), "batch 0 is not done; batches are written in order"),
], ids=lambda v: v if isinstance(v, str) else "")
def test14_bad_input(store, tmp_path, args, message):
    with pytest.raises(LoomError, match=message) as err:
        store.write_batch(*args)
    assert "\n" not in str(err.value) and str(err.value).startswith(store.url)
    assert not list((tmp_path / "run.zarr/frames").rglob("c"))  # no record chunk written
    assert store.done_batches(0) == []


def test15_bad_queries(store):
    # What a user's input can cause names the store (LoomError); a caller's broken contract is a bug
    for call, message in [(lambda: store.counts(frames=[9]), "frame 9 is out of range"),
                          (lambda: store.read_frame(0, batches=[0]), r"batch\(es\) \[0\] not done")]:
        with pytest.raises(LoomError, match=message):
            call()
    for call, message in [(lambda: store.counts(kind="diffuse"), "kind must be direct"),
                          (lambda: store.counts(parity=2), "parity None, 0 or 1"),
                          (lambda: PhotonStore.open(store.url, mode="w"), "mode must be")]:
        with pytest.raises(ValueError, match=message) as err:
            call()
        assert not isinstance(err.value, LoomError)


def test16_read_only(store):
    write_frame(store.url, 0, [100], N_ELEMENTS)
    reader = PhotonStore.open(store.url, mode="r")
    assert len(reader.read_frame(0)) == 100
    with pytest.raises(LoomError, match="read-only"):
        reader.write_batch(0, 1, make_batch(0, 1, 10, N_ELEMENTS, photon_start=50))
    with pytest.raises(LoomError, match="read-only"):
        reader.share_frame(1, 0)


def test17_parity_and_kind_split_add_up(store):
    for f, sizes in enumerate([[4000], [2000, 2000, 4000], [], [1000, 3000]]):
        write_frame(store.url, f, sizes, N_ELEMENTS)
    table = {(k, p): store.counts(k, parity=p) for k in ("direct", "indirect", "all")
             for p in (None, 0, 1)}
    for k in ("direct", "indirect", "all"):
        np.testing.assert_array_equal(table[k, 0] + table[k, 1], table[k, None])
    np.testing.assert_array_equal(table["direct", None] + table["indirect", None],
                                  table["all", None])
    for f in range(4):
        rec = store.read_frame(f)
        for (k, p), counts in table.items():
            keep = np.ones(len(rec), bool) if k == "all" else rec.direct == (k == "direct")
            keep &= True if p is None else rec.parity == p
            np.testing.assert_array_equal(counts[f], np.bincount(rec.element[keep],
                                                                 minlength=N_ELEMENTS))
    assert table["all", None][2].sum() == 0 and len(CATEGORIES) == 4
    np.testing.assert_array_equal(store.counts(frames=[3, 1, 3]), table["all", None][[3, 1, 3]])
    np.testing.assert_array_equal(store.batches_per_frame(), [1, 3, 0, 2])


def test18_shared_frames(store):
    write_frame(store.url, 0, [3000, 3000], N_ELEMENTS)
    write_frame(store.url, 3, [100], N_ELEMENTS)
    store.share_frame(1, 0)
    store.share_frame(1, 0)  # recording it again is harmless (resume)
    store.share_frame(2, 0)
    reader = PhotonStore.open(store.url)
    assert [reader.source_frame(f) for f in range(4)] == [0, 0, 0, 3]
    np.testing.assert_array_equal(reader.read_frame(1).key, reader.read_frame(0).key)
    assert reader.read_frame(2).source_frame == 0 and reader.done_batches(2) == [0, 1]
    assert reader.photons_emitted(1) == reader.photons_emitted(0) and reader.is_done(1, 1)
    table = reader.counts()
    np.testing.assert_array_equal(table[1], table[0])
    np.testing.assert_array_equal(reader.batches_per_frame(), [2, 2, 2, 1])
    with pytest.raises(LoomError, match="frame 1 shares the photons of frame 0; write to 0"):
        store.write_batch(1, 2, make_batch(1, 2, 10, N_ELEMENTS, photon_start=3000))
    for f, g, message in [(1, 3, "frame 1 already shares frame 0"), (3, 3, "its own photons"),
                          (3, 1, "frame 1 itself shares frame 0; share with 0"),
                          (0, 3, "other frames share frame 0"),
                          (3, 0, "frame 3 already has photons of its own")]:
        with pytest.raises(LoomError, match=message):
            store.share_frame(f, g)


def test19_atrium_size_count_table(tmp_path):
    """300 frames x 45,000 elements, some frames with two batches: exact, and read quickly."""
    n_frames, n_elements = 300, 45_000
    store = create(tmp_path / "atrium", n_frames=n_frames, n_elements=n_elements)
    expect = np.zeros((n_frames, n_elements), np.uint32)
    rng = np.random.default_rng(3)
    for f in range(n_frames):
        start = 0
        for b in range(2 if f % 10 == 0 else 1):
            n = 200
            key = rng.integers(0, n_elements, n).astype(np.uint32) | np.uint32(f % 2) << 31
            store.write_batch(f, b, PhotonBatch(key, np.zeros((n, 2), np.uint16), np.ones((n, 3), np.float32),
                                                photons_emitted=100, photon_start=start))
            start += 100
            np.add.at(expect[f], key & ELEMENT_MASK, 1)
    reader = PhotonStore.open(tmp_path / "atrium")
    t0 = time.perf_counter()
    table = reader.counts()
    seconds = time.perf_counter() - t0
    assert table.shape == (n_frames, n_elements) and table.dtype == np.uint32
    np.testing.assert_array_equal(table, expect)
    assert seconds < 5.0, f"count table took {seconds:.2f} s"
    np.testing.assert_array_equal(reader.counts("direct", frames=range(0, 300, 2)),
                                  np.zeros((150, n_elements), np.uint32))
    np.testing.assert_array_equal(reader.counts("direct", frames=[299, 1]), expect[[299, 1]])


def test20_batch_table_is_json_free_of_surprises(store, tmp_path):
    """The done marker holds start, emitted, count and digest; zarr metadata stays valid JSON."""
    write_frame(store.url, 0, [300, 300], N_ELEMENTS)
    info = store.batch_info(0, 1)
    assert info["photon_start"] == 150 and info["photons_emitted"] == 150
    assert info["n_records"] == 300 and info["digest"] > 0 and store.batch_info(0, 2) is None
    for path in (tmp_path / "run.zarr").rglob("zarr.json"):
        json.loads(path.read_text())


def test21_pack_key_bits():
    key = pack_key([0, 5, (1 << 30) - 1], [7, 8, 9], [True, False, False])
    np.testing.assert_array_equal(key, [(1 << 31) | (1 << 30), 5, (1 << 30) | ((1 << 30) - 1)])
    assert key.dtype == np.uint32
    with pytest.raises(ValueError, match="element ids must be in"):
        pack_key([1 << 30], [0], [False])


def test22_verify_batch_detects_changed_records(store):
    write_frame(store.url, 1, [2000], N_ELEMENTS)
    assert store.verify_batch(1, 0) and not store.verify_batch(1, 1)
    rows = zarr.open_array(store.url, path="frames/1/0", mode="r+")  # key, bary, energy R, G, B
    rows[2, 0] = rows[2, 0] + 1
    assert not store.verify_batch(1, 0)


def test23_pickles_by_url(store):
    write_frame(store.url, 0, [100], N_ELEMENTS)
    clone = pickle.loads(pickle.dumps(store))
    assert clone.url == store.url and clone.mode == "r+" and clone.done_batches(0) == [0]
    assert "frames=4" in repr(clone)


def test24_batch_array_is_plain_zarr(store):
    """The record array the store writes itself is an ordinary zarr array of the packed rows."""
    from pipeline.store.records import pack_records, unpack_records

    batch = make_batch(2, 0, 3000, N_ELEMENTS)
    store.write_batch(2, 0, batch)
    rows = zarr.open_array(store.url, path="frames/2/0", mode="r")[...]
    key, bary, energy = expected_sorted(batch)
    np.testing.assert_array_equal(rows, pack_records(key, bary, energy))
    k, b, e, offsets = unpack_records(rows, N_ELEMENTS)
    np.testing.assert_array_equal(k, key)
    np.testing.assert_array_equal(b, bary)
    np.testing.assert_array_equal(e.view(np.uint32), energy.view(np.uint32))
    np.testing.assert_array_equal(np.diff(offsets), np.bincount(key & ELEMENT_MASK, minlength=N_ELEMENTS))


def test25_merge_is_a_stable_sort_by_element():
    parts = []
    for b, n in enumerate([500, 0, 1200, 7]):
        batch = make_batch(0, b, n, N_ELEMENTS)
        key, bary, energy = expected_sorted(batch)
        offsets = np.concatenate([[0], np.cumsum(np.bincount(key & ELEMENT_MASK, minlength=N_ELEMENTS))])
        parts.append((key, bary, energy, offsets))
    got = FrameRecords.merge(0, 0, range(4), parts, N_ELEMENTS, 99)
    key = np.concatenate([p[0] for p in parts])
    order = np.argsort(key & ELEMENT_MASK, kind="stable")
    np.testing.assert_array_equal(got.key, key[order])
    np.testing.assert_array_equal(got.b1, np.concatenate([p[1] for p in parts])[order, 0])
    np.testing.assert_array_equal(got.energy, np.concatenate([p[2] for p in parts])[order])
    check_consistent(got, N_ELEMENTS)


def test26_an_open_store_sees_batches_written_by_others(store):
    """Cached done tables and markers never hide a batch another writer finished meanwhile."""
    reader = PhotonStore.open(store.url, **IDENTITY)
    assert reader.done_batches(0) == [] and reader.prefix_for(0, 10) is None
    write_frame(store.url, 0, [300, 300], N_ELEMENTS)
    assert reader.done_batches(0) == [0, 1] and reader.prefix_for(0, 300) == 2
    time.sleep(0.15)  # old enough for the listing to be reused ...
    assert reader.done_batches(0) == [0, 1]
    write_frame(store.url, 1, [300], N_ELEMENTS)  # ... until the directory changes
    assert reader.done_batches(1) == [0] and reader.photons_in(1, 1) == 150


def test_keep_records_is_part_of_a_stores_identity(tmp_path):
    """A store made with records is not resumed without them, nor one without records with them:
    the refusal says which flag to give or to render elsewhere."""
    with_records = create(tmp_path / "with")
    without = create(tmp_path / "without", keep_records=False)
    assert with_records.keep_records and not without.keep_records
    with pytest.raises(LoomError, match="keeps hit records: give --keep-records to go on with it"):
        create(tmp_path / "with", keep_records=False)
    with pytest.raises(LoomError, match="holds no hit records.*use another --out or --store"):
        PhotonStore.open(tmp_path / "without", keep_records=True)
    assert PhotonStore.open(tmp_path / "without").keep_records is False


def _element_hits(key, bary, energy):
    """A stand-in summary for a store without records: u32 words made from the records."""
    return np.bincount(key & ELEMENT_MASK, minlength=N_ELEMENTS).astype(np.uint32)


def _write(store, frame, sizes, summarise=None, sizes_from=0):
    """write_batch of batches ``sizes`` of a frame in order (batch ``sizes_from`` on); their results."""
    start, out = 0, []
    for b, n in enumerate(sizes):
        batch = make_batch(frame, b, n, N_ELEMENTS, photon_start=start)
        if b >= sizes_from:
            out.append(store.write_batch(frame, b, batch, summarise=summarise))
        start += batch.photons_emitted
    return out


@pytest.mark.parametrize("damage", ["flipped", "truncated", "foreign"])
@pytest.mark.parametrize("keep_records", [True, False], ids=["with records", "sums only"])
def test27_a_damaged_batch_header_is_not_done_and_is_rewritten(tmp_path, damage, keep_records):
    """A batch is done iff its object (batch/c.f.b: header, counts, sums) has a whole header
    naming it: one with a flipped bit, cut short or another batch's is not done, nor is any later
    batch; a rerun rewrites it, finds the later one done again, and the store ends equal to one
    never damaged."""
    summarise = None if keep_records else _element_hits
    sizes = [3000, 3000, 3000]
    damaged, clean = (create(tmp_path / name, keep_records=keep_records) for name in ("damaged", "clean"))
    for store in (damaged, clean):
        assert _write(store, 2, sizes, summarise) == [True] * 3
    assert sorted(p.name for p in (tmp_path / "clean" / "batch").iterdir()) == ["c.2.0", "c.2.1", "c.2.2"]
    if not keep_records:  # one object a batch, nothing else
        assert sorted(p.relative_to(tmp_path / "clean").as_posix() for p in (tmp_path / "clean").rglob("*")
                      if p.is_file() and p.name != "zarr.json") == ["batch/c.2.0", "batch/c.2.1", "batch/c.2.2"]
    path = tmp_path / "damaged" / "batch" / "c.2.1"
    data = bytearray(path.read_bytes())
    if damage == "flipped":
        data[50] ^= 0x04  # inside the header's fields: its CRC-32 no longer matches
    elif damage == "truncated":
        data = data[:60]  # shorter than a header
    else:
        data = bytearray((tmp_path / "damaged" / "batch" / "c.2.0").read_bytes())  # batch 0's object
    path.write_bytes(bytes(data))
    store = PhotonStore.open(damaged.url, mode="r+")  # a new instance, as a rerun opens it
    assert store.done_batches(2) == [0] and not store.is_done(2, 1) and not store.is_done(2, 2)
    assert store.batch_info(2, 1) is None and store.batch_info(2, 2) is None and store.read_summary(2, 1) is None
    assert store.photons_emitted(2) == 1500 and store.batches_per_frame()[2] == 1
    np.testing.assert_array_equal(store.counts(frames=[2]), clean.counts(frames=[2], batches=[1]))
    assert _write(store, 2, sizes, summarise) == [False, True, False]  # batch 1 rewritten, 2 done again
    assert store.done_batches(2) == [0, 1, 2] and store.verify_batch(2, 2)
    assert contents(tmp_path / "damaged") == contents(tmp_path / "clean")


def test28_a_later_batch_that_no_longer_follows_is_not_done_and_is_overwritten(tmp_path):
    """Batch 1 damaged and traced again with other photons (another N_frame): batch 2's object,
    which started where the old batch 1 ended, is not done, and writing batch 2 replaces it."""
    store = create(tmp_path / "s.zarr")
    _write(store, 0, [2000, 2000, 2000])
    (tmp_path / "s.zarr" / "batch" / "c.0.1").write_bytes(b"LOOM")
    rerun = PhotonStore.open(store.url, mode="r+")
    assert _write(rerun, 0, [2000, 4000], sizes_from=1) == [True]
    assert rerun.done_batches(0) == [0, 1] and not rerun.is_done(0, 2)  # batch 2 starts at 2000, not 3000
    assert _write(rerun, 0, [2000, 4000, 1000], sizes_from=2) == [True]
    fresh = PhotonStore.open(store.url)
    assert fresh.done_batches(0) == [0, 1, 2] and fresh.photons_emitted(0) == 1000 + 2000 + 500
    assert len(fresh.read_frame(0)) == 7000 and all(fresh.verify_batch(0, b) for b in range(3))


def test29_a_store_of_format_4_is_refused_in_one_line(tmp_path):
    """Format 4 kept a batch in three objects (done marker, counts chunk, summary): a store of it
    is refused by open and create in one line that says what to do, and nothing is written."""
    old = create(tmp_path / "old.zarr", keep_records=False)
    _write(old, 0, [500], _element_hits)
    meta = tmp_path / "old.zarr" / "zarr.json"
    data = json.loads(meta.read_text())
    data["attributes"]["format_version"] = 4
    meta.write_text(json.dumps(data))
    before = snapshot(tmp_path / "old.zarr")
    for call in (lambda: PhotonStore.open(old.url), lambda: PhotonStore.open(old.url, mode="r+"),
                 lambda: create(old.url, keep_records=False)):
        with pytest.raises(LoomError) as err:
            call()
        message = str(err.value)
        assert "\n" not in message and old.url in message
        assert "format version 4" in message and "reads version 5" in message and "delete it" in message
    assert snapshot(tmp_path / "old.zarr") == before


def test30_a_writer_adds_to_the_running_counts_it_wrote_without_reading_them(tmp_path):
    """The next batch of a frame written by the instance that wrote the one before reads nothing
    back (its running counts are kept); by another instance it reads them from the batch object;
    the stores end byte-identical."""
    one, fresh = (create(tmp_path / name, keep_records=False) for name in ("one", "fresh"))
    start = 0
    for b, n in enumerate([3000, 3000, 6000]):
        batch = make_batch(1, b, n, N_ELEMENTS, photon_start=start)
        start += batch.photons_emitted
        with counting_io() as same:
            one.write_batch(1, b, batch, summarise=_element_hits)
        with counting_io() as other:
            PhotonStore.open(fresh.url, mode="r+").write_batch(1, b, batch, summarise=_element_hits)
        assert same["read_bytes"] == 0 and (other["read_bytes"] > 0) == (b > 0)
    assert contents(tmp_path / "one") == contents(tmp_path / "fresh")
    np.testing.assert_array_equal(PhotonStore.open(one.url).counts(frames=[1]), fresh.counts(frames=[1]))


@pytest.mark.parametrize("element", [N_ELEMENTS, (1 << 30) - 1])
def test31_a_store_without_records_refuses_unknown_elements_too(tmp_path, element):
    """Without records too an unknown element id is refused in one line before anything is
    counted, summed or written, even the largest id."""
    store = create(tmp_path / "s.zarr", keep_records=False)
    batch = make_batch(0, 0, 50, N_ELEMENTS)
    batch.key[7] = (batch.key[7] & ~np.uint32(ELEMENT_MASK)) | np.uint32(element)
    with pytest.raises(LoomError, match=f"element id {element} >= n_elements {N_ELEMENTS}") as err:
        store.write_batch(0, 0, batch, summarise=_element_hits)
    assert "\n" not in str(err.value) and store.done_batches(0) == []
    assert not (tmp_path / "s.zarr" / "batch").exists()


def test32_a_summarisers_hit_counts_are_taken_when_they_add_up(tmp_path):
    """A summarise that returns (words, counts), as pipeline/batch_sums.summariser does, gives the
    store the batch's counts (the same bytes as counting them itself); counts that are not
    (4, n_elements) integers adding up to the records are a caller's bug."""
    plain, given = (create(tmp_path / name, keep_records=False) for name in ("plain", "given"))
    batch = make_batch(0, 0, 4000, N_ELEMENTS)
    plain.write_batch(0, 0, batch, summarise=_element_hits)
    given.write_batch(0, 0, batch, summarise=lambda k, b, e: (_element_hits(k, b, e),
                                                                 category_counts(k, N_ELEMENTS)))
    assert contents(tmp_path / "plain") == contents(tmp_path / "given")
    wrong = category_counts(batch.key, N_ELEMENTS)
    wrong[0, 0] += 1
    for counts in (wrong, wrong[:, :-1], wrong.astype(np.float64)):
        with pytest.raises(TypeError, match="hit counts"):
            given.write_batch(1, 0, batch, summarise=lambda k, b, e, c=counts: (_element_hits(k, b, e), c))
    assert given.done_batches(1) == []
