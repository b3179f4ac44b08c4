"""Shared helpers for the photon store tests: deterministic batches and subprocess workers.

A plain module (not a conftest) so that spawned processes can import the worker functions.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from pipeline.photons.tracing import PhotonBatch
from pipeline.store import PhotonStore, StoreIdentity, pack_key

MADE_BY = StoreIdentity(scene_hash="scene-abc", config_hash="cfg-123", seed=7)
IDENTITY = dict(identity=MADE_BY, keep_records=True)  # the tests read records


def make_batch(frame: int, batch: int, n: int, n_elements: int, *, photon_start: int = 0,
               seed: int = 7) -> PhotonBatch:
    """A random but reproducible batch: skewed element ids, both flags, albedo-like energies."""
    rng = np.random.default_rng([seed, frame, batch])
    lit = np.random.default_rng(n_elements).lognormal(0.0, 1.0, n_elements)  # the "scene"
    lit[::5] = 0.0 if n_elements > 1 else lit[::5]  # a fifth of the elements is never hit
    element = rng.choice(n_elements, n, p=lit / lit.sum()).astype(np.uint32)
    photon = photon_start + rng.integers(0, max(n, 1), n)  # several hits per photon index
    direct = rng.random(n) < 0.4
    key = pack_key(element, photon, direct)
    b1 = rng.integers(0, 65536, n)
    b2 = (rng.random(n) * (65535 - b1)).astype(np.int64)
    bary = np.stack([b1, b2], axis=1).astype(np.uint16)
    albedo = np.array([[0.8, 0.1, 0.1], [0.7, 0.7, 0.7], [0.2, 0.6, 0.3]], np.float32)
    energy = albedo[rng.integers(0, 3, n)] ** rng.integers(0, 4, n)[:, None].astype(np.float32)
    energy = (energy * rng.uniform(0.5, 2.0, (n, 1))).astype(np.float32)
    return PhotonBatch(key, bary, energy, photons_emitted=max(n // 2, 1), photon_start=photon_start)


def write_frame(url: str, frame: int, sizes: list[int], n_elements: int,
                only: list[int] | None = None) -> dict:
    """Write batches 0..len(sizes)-1 of a frame in order (or just ``only``); returns them."""
    store = PhotonStore.open(url, mode="r+", **IDENTITY)
    start, written = 0, {}
    for b, n in enumerate(sizes):
        batch = make_batch(frame, b, n, n_elements, photon_start=start)
        if only is None or b in only:
            store.write_batch(frame, b, batch)
            written[b] = batch
        start += batch.photons_emitted
    return written


def write_frame_task(args) -> int:
    """multiprocessing entry point: (url, frame, sizes, n_elements, only) -> pid."""
    write_frame(*args)
    return os.getpid()


def snapshot(root: Path) -> dict[str, tuple[bytes, int, int]]:
    """Every file under ``root`` (except zarr's temp *.partial): bytes, inode and mtime."""
    files = {}
    for path in sorted(root.rglob("*")):
        if path.is_file() and not path.name.endswith(".partial"):
            st = path.stat()
            files[path.relative_to(root).as_posix()] = (path.read_bytes(), st.st_ino, st.st_mtime_ns)
    return files


def contents(root: Path) -> dict[str, bytes]:
    return {name: data for name, (data, _, _) in snapshot(root).items()}
