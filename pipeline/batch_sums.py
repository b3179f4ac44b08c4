"""What the temporal gather reads of a photon batch: its element sums, made once.

A batch's *summary* is the indirect records' element sums split by photon parity, (E, 2, 3, 4)
(kernels/gather.element_sums_cl, docs/estimators.md §1.2-1.3), followed by its direct records'
vertex flux, (V, 3) (their element sums scattered to the vertices, as the gather scatters the
indirect ones: kernels/gather.corners_to_vertices): everything Steps 3-5 of §5.2 read of the
records. The shoot task makes it while the sorted records are in memory and the store keeps it
beside them (``PhotonStore.write_batch(summarise=...)``) when it is smaller than the records
(:func:`summariser`), so a reconstruction reads about 0.4 MB of sums a ROOM batch of 40,000
photons instead of 1.8 MB of records to unpack and sum, and two workers whose windows reach the
same frames no longer both sum them. A batch without a usable summary (a store written before
summaries, a batch too small for one, a damaged one) is summed from its records by
:func:`batch_summary`, the same function, so the bits do not depend on which path ran.

Stored in float32 (:func:`stored_form`), with sqrt(Q) in Q's slot: the sums are made in float64
and rounded once per batch (relative 6e-8, below the float32 records' own rounding), and the
square root keeps Q, a sum of squared energies, inside float32's range wherever the energies are
(a light 1e30 times as bright squares to 1e60; tests/stress/test_scale.py). Half the bytes of
float64: on the build machines every new page of a written file costs CPU (README "Where the
I/O row's time goes"), and the ROOM summary fell from 842 to 421 KB a batch. A frame's sums are
then added in float64 (:class:`FrameSums`).

One parity split for every use: the unsplit sums of a batch are its even plus its odd sums, and a
frame's sums are its batches' sums added in batch order.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from kernels.gather import corners_to_vertices, element_sums_cl

from .stage_clock import StageClock
from .store.records import RECORD_BYTES

if TYPE_CHECKING:
    from .scene import ElementMesh
    from .store import PhotonStore
    from .store.records import FrameRecords

SLOTS = 2 * 3 * 4  # parity x corner x (R, G, B, Q) values per element


def batch_summary(records: FrameRecords, elements: ElementMesh) -> np.ndarray:
    """The flat float32 summary of one batch's records, as stored (module docstring)."""
    sums = element_sums_cl([records], kind="indirect", split_parity=True)[0]
    # The direct flux from element sums, not per record (workers/reconstruct.records_vertex_flux):
    # the same sum to rounding, over E x 3 corners; a million-record batch took 20 ms the other way
    direct = element_sums_cl([records], kind="direct")[0, :, 0, :, :3]
    flux = corners_to_vertices(direct, elements.element_vertices, elements.n_vertices)
    return stored_form(np.concatenate([sums.reshape(-1), flux.reshape(-1)]), elements)


def stored_form(summary: np.ndarray, elements: ElementMesh) -> np.ndarray:
    """A float64 summary (sums with Q, docs/estimators.md §1.3, then the direct flux) as stored:
    float32 with sqrt(Q)."""
    out = np.array(summary, np.float64)
    q = out[:elements.n_elements * SLOTS].reshape(-1, 4)[:, 3]  # a view: Q of every (element, parity, corner)
    np.sqrt(q, out=q)
    return out.astype(np.float32)


def working_form(stored: np.ndarray, elements: ElementMesh) -> tuple[np.ndarray, np.ndarray]:
    """(sums (E, 2, 3, 4), direct flux (V, 3)), float64, of a stored summary: Q squared back.
    A float64 summary (a store written before float32 ones) is first rounded as a new one is."""
    if stored.dtype != np.float32:
        stored = stored_form(stored, elements)
    n_sums = elements.n_elements * SLOTS
    sums = stored[:n_sums].astype(np.float64).reshape(elements.n_elements, 2, 3, 4)
    sums[..., 3] *= sums[..., 3]
    return sums, stored[n_sums:].astype(np.float64).reshape(elements.n_vertices, 3)


def summary_size(elements: ElementMesh) -> int:
    """Values in a batch's summary on ``elements``: the split indirect sums, then the direct flux."""
    return elements.n_elements * SLOTS + 3 * elements.n_vertices


def summariser(elements: ElementMesh) -> Callable[[FrameRecords], np.ndarray | None]:
    """``write_batch``'s ``summarise`` for batches bucketed on ``elements``: the batch's summary
    when it is smaller than its records (20 bytes each), else None. A fine mesh and a small batch
    (ATRIUM's 43,000 elements: 4.2 MB of sums against 2.6 MB for 130,000 records) would store more
    than the records and read slower than summing them, which the reader then does."""
    size = summary_size(elements) * 4
    return lambda records: batch_summary(records, elements) if size <= RECORD_BYTES * len(records) else None


@dataclass
class SummedFrame:
    """What the gather reads of one frame: element sums (E, P, 3, 4) of a kind, the direct
    photons' vertex flux (V, 3) (None for kinds other than indirect) and the photons emitted."""

    sums: np.ndarray
    direct_flux: np.ndarray | None
    photons_emitted: int

    @property
    def nbytes(self) -> int:
        return self.sums.nbytes + (0 if self.direct_flux is None else self.direct_flux.nbytes)

    def direct_irradiance(self, vertex_areas: np.ndarray) -> np.ndarray:
        """The frame's own direct estimate (workers/reconstruct.records_irradiance's, its flux summed
        per element first)."""
        from workers.reconstruct import flux_to_irradiance

        return flux_to_irradiance(self.direct_flux, self.photons_emitted, vertex_areas)


class FrameSums:
    """Per-process cache of single batches' sums (least recently used out first, at most
    ``max_bytes``): a batch is read once per worker, however many chunks' windows reach its frame
    and however many doublings of N_frame (§5.2.3) use it. Keyed by store, source frame, batch, its
    digest and kind, so a rewritten store never serves stale sums, and frames that share another
    frame's photons share its entries."""

    def __init__(self, max_bytes: int):
        self.max_bytes, self.bytes = int(max_bytes), 0
        self._entries: OrderedDict = OrderedDict()

    def get(self, store: PhotonStore, frame_index: int, n_batches: int | None, kind: str, n_parity: int,
            elements: ElementMesh, *, times: dict[str, float] | None = None) -> SummedFrame:
        """The sums of ``frame_index``'s first ``n_batches`` batches (None: every done batch),
        split by parity (``n_parity`` 2) or not (1); ``times`` gets ``read_s`` (summaries or
        records read) and ``frame_sums_s`` (records summed where no summary was stored)."""
        src = store.source_frame(frame_index)
        chosen = store.done_batches(src) if n_batches is None else list(range(n_batches))
        if not chosen:
            raise ValueError(f"frame {frame_index} has no batches to sum")
        parts = [self._batch(store, src, b, kind, elements, times) for b in chosen]
        sums = [p.sums if n_parity == 2 else p.sums[:, :1] + p.sums[:, 1:] for p in parts]
        total = sums[0].copy() if len(parts) > 1 else sums[0]
        flux = None if parts[0].direct_flux is None else \
            parts[0].direct_flux.copy() if len(parts) > 1 else parts[0].direct_flux
        for s, p in zip(sums[1:], parts[1:]):
            total += s
            if flux is not None:
                flux += p.direct_flux
        return SummedFrame(total, flux, sum(p.photons_emitted for p in parts))

    def _batch(self, store, src: int, batch: int, kind: str, elements, times: dict | None) -> SummedFrame:
        info = store.batch_info(src, batch) or {}
        key = (store.url, src, batch, info.get("digest"), kind)
        found = self._entries.get(key)
        if found is not None:
            self._entries.move_to_end(key)
            return found
        clock = StageClock(times)
        if kind == "indirect":
            entry = self._summary(store, src, batch, elements, int(info["photons_emitted"]), clock)
        else:  # no summary holds other kinds (benchmarks and tests ask for them)
            records = store.read_frame(src, batches=[batch])
            clock.lap("read_s")
            entry = SummedFrame(element_sums_cl([records], kind=kind, split_parity=True)[0], None,
                                int(records.photons_emitted))
            clock.lap("frame_sums_s")
        for a in (entry.sums, entry.direct_flux):
            if a is not None:
                a.flags.writeable = False  # shared by every later reader
        self._put(key, entry)
        return entry

    @staticmethod
    def _summary(store, src: int, batch: int, elements, photons_emitted: int, clock: StageClock) -> SummedFrame:
        """A batch's indirect sums and direct flux: its stored summary, else summed from its records."""
        summary = store.read_summary(src, batch)
        if summary is not None and summary.size != summary_size(elements):
            summary = None  # made on another element mesh: the store's identity check missed it
        if summary is None:
            records = store.read_frame(src, batches=[batch])
            clock.lap("read_s")
            summary = batch_summary(records, elements)
            clock.lap("frame_sums_s")
        else:
            clock.lap("read_s")
        return SummedFrame(*working_form(summary, elements), photons_emitted)

    def _put(self, key, entry: SummedFrame) -> None:
        old = self._entries.pop(key, None)
        self.bytes -= 0 if old is None else old.nbytes
        if entry.nbytes > self.max_bytes:
            return
        self._entries[key] = entry
        self.bytes += entry.nbytes
        while self.bytes > self.max_bytes:
            _, gone = self._entries.popitem(last=False)
            self.bytes -= gone.nbytes


FRAME_SUMS = FrameSums(1 << 30)  # ATRIUM (43,000 elements): ~120 batches of split sums
