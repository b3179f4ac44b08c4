"""pipeline/collection/maps.window_counts: Condition (1) counts the indirect hits (the photons of the map the
windows collect), so a frame where only the direct light changes does not cut the windows of the
indirect map; with every hit counted, as §4's tables, it would."""
from __future__ import annotations

import numpy as np

from pipeline.collection.maps import WindowSpec, collection_windows, window_counts
from pipeline.config import CollectionConfig
from pipeline.photons.tracing import PhotonBatch
from pipeline.store import PhotonStore, pack_key
from tests.store.photonstore_helpers import IDENTITY

FRAMES, EMITTED, CHANGE = 9, 1000, 4
INDIRECT, DIRECT = 400, (50, 800)  # hits of element 0 a frame: direct jumps at CHANGE, indirect does not


def _store(tmp_path) -> PhotonStore:
    url = str(tmp_path / "p.zarr")
    PhotonStore.create(url, n_frames=FRAMES, n_elements=2, frame_numbers=list(range(1, FRAMES + 1)), **IDENTITY)
    store = PhotonStore.open(url, mode="r+", **IDENTITY)
    for f in range(FRAMES):
        n_direct = DIRECT[f >= CHANGE]
        n = INDIRECT + n_direct
        direct = np.arange(n) < n_direct
        store.write_batch(f, 0, PhotonBatch(pack_key(np.zeros(n, np.uint32), np.arange(n), direct),
                                            np.zeros((n, 2), np.uint16), np.ones((n, 3), np.float32),
                                            photons_emitted=EMITTED, photon_start=0))
    return PhotonStore.open(url, mode="r", **IDENTITY)


def _windows(store, config, frame, counts):
    back, fwd = collection_windows(counts, store.emitted(None).astype(np.float64), [frame], WindowSpec("adaptive", 8),
                                   config)
    return int(back[0, 0]), int(fwd[0, 0])


def test_windows_follow_the_indirect_hits(tmp_path):
    store = _store(tmp_path)
    config = CollectionConfig(step_levels=0)  # Condition (1) alone: no element regions needed
    assert window_counts(store)[:, 0].tolist() == [INDIRECT] * FRAMES
    every = store.counts(kind="all")
    assert every[:, 0].tolist() == [INDIRECT + DIRECT[f >= CHANGE] for f in range(FRAMES)]
    # The frame after the direct light's jump: its window reaches back over it only on indirect counts
    assert _windows(store, config, CHANGE, window_counts(store)) == (4, 4)
    back, _ = _windows(store, config, CHANGE, every)
    assert back == (config.min_extent - 1) // 2  # the centred minimal extent only
    # Both kinds of hit stay in the store: the choice is only what the windows read
    assert store.counts(kind="direct")[:, 0].tolist() == [DIRECT[f >= CHANGE] for f in range(FRAMES)]


def test_no_adaptive_window_crosses_a_frame_without_indirect_light():
    # Frames 0-4 record no indirect photon (a lamp not yet on), 5-9 do, evenly: every adaptive
    # window stays on its side; a dark frame's is itself; fixed windows pool regardless
    counts = np.zeros((10, 3), np.uint32)
    counts[5:] = 400
    emitted = np.full(10, 1000.0)
    config = CollectionConfig(step_levels=0)
    back, fwd = collection_windows(counts, emitted, range(10), WindowSpec("adaptive", 8), config)
    assert not back[:5].any() and not fwd[:5].any()
    assert back[5].max() == 0 and back[9].min() == 4 and fwd[5].min() == 4  # the lit frames pool among themselves
    back, fwd = collection_windows(counts, emitted, range(10), WindowSpec("fixed", 8), config)
    assert back[5].min() == 4 and fwd[4].min() == 4
