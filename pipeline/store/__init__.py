"""The photon store: what a render reads of every photon batch, on zarr v3, written once per (frame, batch).

Photons are the only state of a run that costs tracing; everything downstream (temporal windows,
illumination maps, frames) is recomputed from what the store keeps of them and the config
(docs/03-conventions.md §5). Every stage reads a batch through two things: its per-element hit
counts (Condition (1), p_me, the step test) and its *sums*, the sufficient statistics of the
gather (per element, corner and parity the indirect energy sums and sums of squares, and the
direct flux per vertex; pipeline/collection/batch_sums.py, sparse where a batch hits few elements). The
store keeps those for every batch; the raw hit records only when made with ``keep_records``
(``loom render --keep-records``), for re-estimation and research: the default ROOM render's
store takes a few bytes a photon (docs/04-photons.md §3) where its records took about 40.

Record (docs/05-estimators.md §1.1), exactly ``RECORD_BYTES`` = 20 bytes uncompressed, stored struct-of-arrays::

    key     u32     4 B  bits 0-29 element id, bit 30 photon-index parity (1 = odd), bit 31 direct
    bary    2 x u16 4 B  b1, b2 fixed point /65535 (b0 = 1 - b1 - b2)
    energy  3 x f32 12 B RGB energy (throughput x per-photon power, scaled by the tracer)

On disk the records of a batch are one (5, n) u32 array, rows key, b1 | b2 << 16 and the bits
of energy R, G, B (struct-of-arrays in one chunk), blosc lz4 + byte shuffle: a ROOM frame at
40,000 photons (125,000 records) takes about 14.1 bytes a record.

On disk (``F`` frames, ``B`` = max_batches, ``E`` elements), format version 5 (a store of another
version is refused with a one-line error saying to delete it or render elsewhere)::

    run.zarr/
      zarr.json          group; attributes: format, format_version, scene_hash, config_hash, seed,
                         keep_records, n_frames, n_elements, frame_numbers, max_batches,
                         record_layout, batch_fields, count_categories, complete
      source/            (F,) i32, one chunk, -1 or the frame whose photons frame f reuses
      batch/c.f.b        not a zarr array: one object a batch, written last by its writer in one
                         write; it is the batch's done marker (below). A header of 104 bytes: the
                         magic "LOOMBAT5", then u64 each: f, b, photon_start, photons_emitted,
                         n_records, digest, the counts' length and CRC-32, the summary's word count
                         (2^64 - 1: none), length and CRC-32, and the CRC-32 of the header before it.
                         Then two blosc lz4 + shuffle blocks of u32:
                         counts (4, E): hits of batches 0..b (running sum) per category
                           indirect-even, indirect-odd, direct-even, direct-odd (the batch's own
                           counted by the summariser's grouping of its records, or by the store);
                         summary: the batch's sums as words (pipeline/collection/batch_sums.py), derived by its
                           writer from the records (``write_batch(summarise=...)``). A summary
                           whose length or CRC does not match is ignored with a warning
                           (:meth:`PhotonStore.read_summary`): the reader sums the records instead
                           where the store keeps them, and refuses in one line where it does not;
                           damaged counts are refused in one line
      frames/<f>/        only with keep_records: group per frame
        <b>              (5, n) u32 array, chunk (5, 2^20), keys "c.0.i", made by the writer of
                         (f, b) and by nobody else; records sorted by element (an element's
                         records are contiguous: the reader recovers the offsets from the keys)

Done. Batch b of frame f is done iff ``batch/c.f.b`` exists with a whole header (magic and CRC
right) naming (f, b), batches 0..b-1 are done and it starts where batch b-1 ends
(:meth:`PhotonStore._prefixes`): done batches are a prefix 0..k-1. A header that is cut short,
has a flipped bit or belongs to another batch's object makes its batch (and the later ones) not
done, and a rerun writes it again; a later object that no longer follows (its batch b-1 traced
again with another photon count) is not done either and is replaced when its batch is written.
Damage past a whole header (the counts or the summary) is found by their CRCs where they are read.

Why this layout. A batch of a store without records is one new file: its done marker, running
counts and sums arrive together, whole or not at all, and a render reads its header (the done
table, photon counts), its counts (the windows) and its summary (the gather) from byte ranges of
it. Format 4 wrote three files a batch (counts chunk, summary, then a 40-byte done marker in a
second write) and hashed the summary twice with SHA-256; the per-batch I/O that remains is this
one file, the previous batch's counts it adds to, and the summary read back by each worker that
gathers the batch. Record counts per batch are unknown until traced and vary 2x per doubling
(§5.2.3), so with ``keep_records`` each batch gets its own exactly-sized array, created by its
writer at ``frames/<f>/<b>``: in zarr v3 that writes only metadata inside the batch's own prefix
(parents exist), so no shared metadata and no resize. Its metadata and chunks are written as whole
objects by the store itself (``_Raw``): two file writes where four zarr arrays cost about 50 ms of
zarr calls. zarr reads the record arrays and ``source`` as any other. An object belongs to exactly
one (frame, batch), so concurrent writers never share one (zarr 3 has no locks). Objects of a
directory are files of that one directory (``c.f.b``): a new directory costs about 1 ms on ext4
against 0.1 ms for a new file. Counts are running sums so the frames x elements table is one
read per frame (300 x 45,000 in well under a second) rather than one per batch; a reconstruction
chunk reads only the rows its windows can reach (pipeline/collection/maps.py).

Digest and checks. The header's digest is the first 64 bits of SHA-256 over the batch's packed
rows (as on disk, uncompressed) and (photon_start, photons_emitted) where records are kept, else
over its summary words and its own hit counts (u32) and the same two numbers, one pass
(records.parts_digest): what a rewrite of a done batch is compared by, and what
:meth:`PhotonStore.verify_batch` checks kept records against. SHA-256 runs in hardware on current
x86 and ARM cores (about 1.5 ms for the rows of a ROOM batch of 125,000 records, 0.3 ms for its
summary and counts). Damage is told by CRC-32 (zlib, a few times faster): of the header, and of
the counts and summary blocks as stored, so a reader checks what it reads before decompressing it,
without hashing the words again.

Atomicity and idempotence. LocalStore writes every chunk as temp file + rename, and so does the
store's own writer (record arrays, batch objects, illumination maps), so an object is whole or
absent. A writer writes the records first (if kept) and the batch object last, in a second write,
so a killed writer leaves a batch that is not done, which a rerun rewrites. Records are sorted into
a total order (element, key, b1, b2, energy bits), so the bytes do not depend on input order, and
a rerun writes identical bytes over identical objects (existing arrays are reused, never deleted,
so a duplicate task cannot expose a done batch with missing chunks). Writing a batch that is
already done only compares digests. Batch b needs batch b-1 done and starts at its photon end, so
a done batch never changes once written. ``file://`` URLs map to LocalStore for these guarantees
(fsspec's local filesystem neither renames atomically nor makes parent directories); other fsspec
URLs rely on the object store writing each object whole. A killed writer may leave ``*.partial``
temp files, which zarr never reads.

Caches. A store instance reads each done batch's header once (it never changes), and a writer
keeps the running counts of the last batch it wrote of each frame (up to ``RUNNING_CACHE_BYTES``,
64 MiB), so that the frame's next batch, when it writes that one too, adds to them without reading
them back. On a LocalStore it also reuses the done table (one directory listing and the headers not
yet read) and the sources while the ``batch/`` directory and the ``source`` chunk are unchanged
(stat), so the hundreds of small queries of a reconstruction task cost microseconds, and a batch
another process finishes is still seen. Instances from :meth:`PhotonStore.open_shared` (one per
worker process) also keep decoded frames (``read_frame`` of done batches, which never change) up to
``RECORD_CACHE_BYTES`` (192 MiB), least recently used out first, their arrays read-only:
reconstruction chunks next to each other reach the same F_max frames, and the second one on a
worker decodes none of them again. The hot paths' batch-sized temporaries (the hit counts' keys, a
summary read and decompressed) live in per-thread scratch arrays (records.scratch): a new page
costs 3-33 us on the build machines, several ms a batch.

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
    BATCH_MAGIC,
    FORMAT,
    FORMAT_VERSION,
    RECORD_CHUNK,
    PhotonStore,
    StoreIdentity,
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
           "BARY_SCALE", "BATCH_FIELDS", "BATCH_MAGIC", "CATEGORIES", "DIRECT_BIT", "ELEMENT_BITS",
           "ELEMENT_MASK", "FORMAT", "FORMAT_VERSION", "PARITY_BIT", "RECORD_BYTES",
           "RECORD_CHUNK", "FrameRecords", "PhotonStore", "StoreIdentity", "pack_key", "records_digest",
           "sort_records"]
