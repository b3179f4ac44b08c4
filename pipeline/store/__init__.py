"""The photon store: what a render reads of every photon batch, on zarr v3, written once per (frame, batch).

Photons are the only state of a run that costs tracing; everything downstream (temporal windows,
illumination maps, frames) is recomputed from what the store keeps of them and the config
(docs/conventions.md §5). Every stage reads a batch through two things: its per-element hit
counts (Condition (1), p_me, the step test) and its *sums*, the sufficient statistics of the
gather (per element, corner and parity the indirect energy sums and sums of squares, and the
direct flux per vertex; pipeline/batch_sums.py, sparse where a batch hits few elements). The
store keeps those for every batch; the raw hit records only when made with ``keep_records``
(``loom render --keep-records``), for re-estimation and research: the default ROOM render's
store takes a few bytes a photon (README, "Photon shooting") where its records took about 40.

Record (docs/estimators.md §1.1), exactly ``RECORD_BYTES`` = 20 bytes uncompressed, stored struct-of-arrays::

    key     u32     4 B  bits 0-29 element id, bit 30 photon-index parity (1 = odd), bit 31 direct
    bary    2 x u16 4 B  b1, b2 fixed point /65535 (b0 = 1 - b1 - b2)
    energy  3 x f32 12 B RGB energy (throughput x per-photon power, scaled by the tracer)

On disk the records of a batch are one (5, n) u32 array, rows key, b1 | b2 << 16 and the bits
of energy R, G, B (struct-of-arrays in one chunk), blosc lz4 + byte shuffle: a ROOM frame at
40,000 photons (125,000 records) takes about 14.1 bytes a record.

On disk (``F`` frames, ``B`` = max_batches, ``E`` elements), format version 4 (a store of another
version is refused with a one-line error saying to delete it or render elsewhere)::

    run.zarr/
      zarr.json          group; attributes: format, format_version, scene_hash, config_hash, seed,
                         keep_records, n_frames, n_elements, frame_numbers, max_batches,
                         record_layout, complete
      batch/             (F, B, 5) u64, chunk (1, 1, 5) uncompressed (40 bytes), keys "c.f.b.0":
                         [DONE_MAGIC, photon_start, photons_emitted, n_records, digest]; a chunk
                         exists <=> the batch is done
      counts/            (F, B, 4, E) u32, chunk (1, 1, 4, E), lz4 + shuffle, keys "c.f.b.0.0":
                         hits of batches 0..b (running sum) per category indirect-even,
                         indirect-odd, direct-even, direct-odd
      source/            (F,) i32, one chunk, -1 or the frame whose photons frame f reuses
      summaries/c.f.b    not a zarr array: the batch's sums as u32 words (pipeline/batch_sums.py),
                         derived by its writer from the sorted records (``write_batch(summarise=...)``)
                         and written before the done marker: "LOOMSUM5", the batch digest, the word
                         count and the words' own digest (u64 each), then blosc lz4 + shuffle. A
                         summary whose digests do not match is ignored with a warning
                         (:meth:`PhotonStore.read_summary`): the reader sums the records instead
                         where the store keeps them, and refuses in one line where it does not
      frames/<f>/        only with keep_records: group per frame
        <b>              (5, n) u32 array, chunk (5, 2^20), keys "c.0.i", made by the writer of
                         (f, b) and by nobody else; records sorted by element (an element's
                         records are contiguous: the reader recovers the offsets from the keys)

Why this layout. Record counts per batch are unknown until traced and vary 2x per doubling
(§5.2.3), so each batch gets its own exactly-sized array, created by its writer at
``frames/<f>/<b>``: in zarr v3 that writes only metadata inside the batch's own prefix (parents
exist), so no shared metadata and no resize. One array a batch, its metadata and chunks written as
whole objects by the store itself (``_Raw``), costs two file writes where four zarr arrays cost
about 50 ms of zarr calls. The store also encodes and writes the batch's ``counts`` chunk and its
done marker itself, and reads both (and the count table) straight from their chunks: zarr's array
calls cost about 3 ms a batch there. zarr reads every chunk as its own. A preallocated (frame,
capacity) layout would need a capacity guess and coordinator resizes. The small fixed-size tables
(batch, counts, source) are made by the coordinator in :meth:`PhotonStore.create`; a chunk of them
belongs to exactly one (frame, batch), so concurrent writers never share a chunk (zarr 3 has no
locks). Every chunk key uses "." (``c.f.b.0``): an array's chunks are files of its one directory. A
new directory costs about 1 ms on ext4 against 0.1 ms for a new file, and "/" keys made five new
directories per batch and four per frame of maps. Counts are running sums so the frames x elements
table is one chunk read per frame (300 x 45,000 in well under a second) rather than one per batch;
a reconstruction chunk reads only the rows its windows can reach (pipeline/temporal.py).

Digest. The done marker's digest is the first 64 bits of SHA-256 over the batch's packed rows (as
on disk, uncompressed) and (photon_start, photons_emitted), computed whether or not the records
are kept: what a rewrite of a done batch is compared by, what ties a summary to its batch, and
what :meth:`PhotonStore.verify_batch` checks kept records against. SHA-256 runs in
hardware on current x86 and ARM cores (1.5 ms for a ROOM batch of 125,000 records).

Atomicity and idempotence. LocalStore writes every chunk as temp file + rename, and so does the
store's own writer (record arrays, counts, done markers, illumination maps), so a chunk is whole or
absent. A writer writes counts, sums and records first and the ``batch`` chunk last, in a second write:
that chunk is the done marker, so a killed writer leaves a batch that is not done, which a rerun
rewrites. Records are sorted into a total order (element, key, b1, b2, energy bits), so the bytes
do not depend on input order, and a rerun writes identical bytes over identical chunks (existing
arrays are reused, never deleted, so a duplicate task cannot expose a done batch with missing
chunks). Writing a batch that is already done only compares digests. Batch b needs batch b-1 done
and starts at its photon end, so done batches are a prefix 0..k-1 and batch b never changes once
written. ``file://`` URLs map to LocalStore for these guarantees (fsspec's local filesystem neither
renames atomically nor makes parent directories); other fsspec URLs rely on the object store
writing each object whole. A killed writer may leave ``*.partial`` temp files, which zarr never
reads.

Caches. A store instance reads each done marker once (it never changes). On a LocalStore it also
reuses the done table (one directory listing) and the sources while the ``batch/`` directory
and the ``source`` chunk are unchanged (stat), so the hundreds of small queries of a
reconstruction task cost microseconds, and a batch another process finishes is still seen.
Instances from :meth:`PhotonStore.open_shared` (one per worker process) also keep decoded frames
(``read_frame`` of done batches, which never change) up to ``RECORD_CACHE_BYTES`` (192 MiB), least
recently used out first, their arrays read-only: reconstruction chunks next to each other reach
the same F_max frames, and the second one on a worker decodes none of them again.

Illumination maps (``illumination/``, pipeline/store/illumination.py) live in the same group.

I/O. Every object the store and the maps read or write passes one place (``_Raw``), which adds
its bytes to the calling thread's count inside :func:`counting_io`: the shoot and reconstruction
tasks report what they moved, and Table 2 says it per frame (pipeline/benchmarks/render.py).

Modules: ``records`` (the record, validation, total order; pure NumPy), ``photon_store`` (zarr),
``illumination`` (the per-frame maps).
"""
from __future__ import annotations

from .photon_store import (
    BATCH_FIELDS,
    DONE_MAGIC,
    FORMAT,
    FORMAT_VERSION,
    RECORD_CHUNK,
    PhotonStore,
    counting_io,
    disk_usage,
    remove_partials,
)
from .records import (
                           BARY_SCALE,
                           CATEGORIES,
                           DIRECT_BIT,
                           ELEMENT_BITS,
                           ELEMENT_MASK,
                           PARITY_BIT,
                           RECORD_BYTES,
                           FrameRecords,
                           pack_key,
                           records_digest,
                           sort_records,
)

__all__ = ["counting_io", "disk_usage", "remove_partials",
           "BARY_SCALE", "BATCH_FIELDS", "CATEGORIES", "DIRECT_BIT", "DONE_MAGIC", "ELEMENT_BITS",
           "ELEMENT_MASK", "FORMAT", "FORMAT_VERSION", "PARITY_BIT", "RECORD_BYTES",
           "RECORD_CHUNK", "FrameRecords", "PhotonStore", "pack_key", "records_digest",
           "sort_records"]
