"""What the temporal gather reads of a photon batch: its element sums, made once, stored sparse.

A batch's *summary* is the indirect records' element sums split by photon parity, (E, 2, 3, 4)
(kernels/gather.element_sums_cl, docs/05-estimators.md §1.2-1.3), and its direct records' vertex
flux, (V, 3) (their element sums scattered to the vertices, as the gather scatters the indirect
ones: kernels/gather.corners_to_vertices): everything Steps 3-5 of §5.2 read of the records, so
the photon store keeps it for every batch and the records only on request (pipeline/store). The
shoot task makes it while the records are in memory (:func:`summariser`).

Stored in float32, with sqrt(Q) in Q's slot: the sums are made in float64 and rounded once per
batch (relative 6e-8, below the float32 records' own rounding), and the square root keeps Q, a
sum of squared energies, inside float32's range wherever the energies are (a light 1e30 times as
bright squares to 1e60; tests/stress/test_scale.py). A frame's sums are then added in float64
(:class:`FrameSums`).

Sparse: only the elements and vertices a batch hit are stored, each with its index, as u32 words
(:func:`encode`)::

    E, V, n_e, n_v | element ids (n_e) | their 24 sums (n_e x 2 x 3 x 4 float32 bits)
                   | vertex ids (n_v)  | their direct flux (n_v x 3 float32 bits)

A small batch on a fine mesh (ATRIUM's at the paper's size, 43,000 elements) stores the elements it hit, not 4.2 MB of
mostly zero sums; a large batch pays 4 bytes an element over the dense form. The reader scatters
them into zeros (:func:`decode`): the same bits as the dense sums.

One parity split for every use: the unsplit sums of a batch are its even plus its odd sums, and a
frame's sums are its batches' sums added in batch order.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from kernels.gather import corners_to_vertices, element_sums_cl
from pipeline.collection.estimators import flux_to_irradiance
from pipeline.errors import LoomError
from pipeline.stage_clock import StageClock
from pipeline.store.records import FrameRecords, element_grouped

if TYPE_CHECKING:
    from pipeline.scene import ElementMesh
    from pipeline.store import PhotonStore

SLOTS = 2 * 3 * 4  # parity x corner x (R, G, B, Q) values per element
HEADER = 4  # E, V, n_e, n_v


def batch_summary(records: FrameRecords, elements: ElementMesh) -> np.ndarray:
    """The u32 words of the summary of one batch's records grouped by element, as stored (module
    docstring)."""
    sums = element_sums_cl([records], kind="indirect", split_parity=True)[0]
    # The direct flux from element sums, not per record (pipeline/collection/estimators.records_vertex_flux):
    # the same sum to rounding, over E x 3 corners; a million-record batch took 20 ms the other way
    direct = element_sums_cl([records], kind="direct")[0, :, 0, :, :3]
    flux = corners_to_vertices(direct, elements.element_vertices, elements.n_vertices)
    return encode(sums, flux)


def encode(sums: np.ndarray, flux: np.ndarray) -> np.ndarray:
    """u32 words of float64 sums (E, 2, 3, 4) with Q (docs/05-estimators.md §1.3) and direct flux
    (V, 3): float32, sqrt(Q) in Q's slot, the rows that are not all zero with their indices."""
    rows = np.array(sums, np.float64).reshape(sums.shape[0], SLOTS)
    q = rows.reshape(-1, 4)[:, 3]  # a view: Q of every (element, parity, corner)
    np.sqrt(q, out=q)
    rows, flux = rows.astype(np.float32), np.asarray(flux, np.float64).astype(np.float32)
    hit_e, hit_v = np.flatnonzero(rows.any(axis=1)), np.flatnonzero(flux.any(axis=1))
    head = np.array([rows.shape[0], flux.shape[0], hit_e.size, hit_v.size], np.uint32)
    return np.concatenate([head, hit_e.astype(np.uint32), rows[hit_e].reshape(-1).view(np.uint32),
                           hit_v.astype(np.uint32), flux[hit_v].reshape(-1).view(np.uint32)])


def decode(words: np.ndarray, elements: ElementMesh) -> tuple[np.ndarray, np.ndarray]:
    """(sums (E, 2, 3, 4), direct flux (V, 3)), float64, of a summary's words: Q squared back.
    ValueError when the words do not describe a summary on ``elements``."""
    words = np.asarray(words, np.uint32)
    if words.size < HEADER:
        raise ValueError("summary shorter than its header")
    n_el, n_vx, n_e, n_v = (int(w) for w in words[:HEADER])
    if (n_el, n_vx) != (elements.n_elements, elements.n_vertices):
        raise ValueError(f"summary of {n_el} elements and {n_vx} vertices, the mesh has {elements.n_elements} "
                         f"and {elements.n_vertices}")
    if words.size != HEADER + n_e * (1 + SLOTS) + n_v * 4:
        raise ValueError(f"summary of {words.size} words does not hold {n_e} elements and {n_v} vertices")
    at = HEADER
    hit_e = words[at:at + n_e]
    at += n_e
    rows = words[at:at + n_e * SLOTS].view(np.float32).reshape(n_e, SLOTS)
    at += n_e * SLOTS
    hit_v = words[at:at + n_v]
    at += n_v
    values = words[at:].view(np.float32).reshape(n_v, 3)
    if (n_e and hit_e.max() >= n_el) or (n_v and hit_v.max() >= n_vx) or not (
            np.isfinite(rows).all() and np.isfinite(values).all()):
        raise ValueError("summary index out of range or value not finite")
    sums = np.zeros((n_el, SLOTS), np.float64)
    sums[hit_e] = rows
    sums = sums.reshape(n_el, 2, 3, 4)
    sums[..., 3] *= sums[..., 3]
    flux = np.zeros((n_vx, 3), np.float64)
    flux[hit_v] = values
    return sums, flux


def summariser(elements: ElementMesh) -> Callable[[np.ndarray, np.ndarray, np.ndarray],
                                                 tuple[np.ndarray, np.ndarray]]:
    """``write_batch``'s ``summarise`` for batches bucketed on ``elements``: the batch's records
    (key, bary, energy as the tracer gave them) grouped by element, each element's in that order
    (pipeline/store/records.element_grouped), and summed. The tracer's order is deterministic
    (pipeline/photons/tracing.py), so the sums are; a damaged summary re-made from kept records, which are
    stored in the total order, agrees with it to float32 rounding, not always to the bit. Returns
    the summary's words and the batch's hit counts per category and element, which the grouping
    counts anyway (the store takes them instead of counting the records again)."""
    def summarise(key: np.ndarray, bary: np.ndarray, energy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        *grouped, counts = element_grouped(key, bary, energy, elements.n_elements, with_counts=True)
        return batch_summary(FrameRecords.merge(0, 0, (0,), [grouped], elements.n_elements, 1), elements), counts
    return summarise


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
        """The frame's own direct estimate (pipeline/collection/estimators.records_irradiance's, its flux summed
        per element first)."""
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
        records read) and ``frame_sums_s`` (records summed: kinds other than indirect, or a
        damaged summary in a store that keeps records)."""
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
        else:  # no summary holds other kinds (benchmarks and tests ask for them, with records)
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
        """A batch's indirect sums and direct flux: its stored summary; if that is damaged, summed
        from its records where the store keeps them."""
        try:  # decoded from the store's scratch arrays: no new memory for the read (PhotonStore.read_summary)
            parts = store.read_summary(src, batch, use=lambda words: decode(words, elements))
        except ValueError:
            parts = None  # made on another element mesh, or damaged past its CRC: the records decide
        if parts is not None:
            clock.lap("read_s")
            return SummedFrame(*parts, photons_emitted)
        if not store.keep_records:
            raise LoomError(f"frame {src} batch {batch}: batch sums missing or damaged and no hit records kept; "
                            "delete the photon store to trace its photons again", path=store.url)
        records = store.read_frame(src, batches=[batch])
        clock.lap("read_s")
        parts = decode(batch_summary(records, elements), elements)
        clock.lap("frame_sums_s")
        return SummedFrame(*parts, photons_emitted)

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


FRAME_SUMS = FrameSums(1 << 30)  # ATRIUM on the paper's mesh (43,000 elements): ~120 batches of split sums
