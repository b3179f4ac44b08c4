"""Helpers for the shooting tests: a store fingerprint that compares every stored value."""
from __future__ import annotations

import hashlib

import numpy as np

from pipeline.store import PhotonStore


def store_fingerprint(url: str) -> str:
    """Digest of every frame's batch table, sharing, count tables and batch sums, and of its
    records where the store keeps them."""
    store = PhotonStore.open(url)
    h = hashlib.sha256()
    for f in range(store.n_frames):
        h.update(np.int64(store.source_frame(f)).tobytes())
        for b in store.done_batches(f):
            h.update(repr(sorted(store.batch_info(f, b).items())).encode())
            h.update(store.read_summary(f, b).tobytes())
        if store.keep_records:
            recs = store.read_frame(f)
            for name in ("key", "b1", "b2", "energy", "offsets"):
                h.update(np.ascontiguousarray(getattr(recs, name)).tobytes())
    h.update(store.counts("all").tobytes())
    return h.hexdigest()
