"""The photon store: every photon hit of a run, on zarr v3, written once per (frame, batch).

Photons are the only state of a run that costs tracing; everything downstream (temporal windows,
illumination maps, frames) is recomputed from them and the config (DESIGN.md, "The photon store").

Record (dept.md §1.1), exactly ``RECORD_BYTES`` = 20 bytes uncompressed, stored struct-of-arrays::

    key     u32     4 B  bits 0-29 element id, bit 30 photon-index parity (1 = odd), bit 31 direct
    bary    2 x u16 4 B  b1, b2 fixed point /65535 (b0 = 1 - b1 - b2)
    energy  3 x f32 12 B RGB energy (throughput x per-photon power, scaled by the tracer)

On disk (blosc zstd-3 + byte shuffle) a random 1,000,000-record batch on 45,000 elements takes
13.3 bytes a record (key 0.2, bary 4.0, energy 9.1), plus 0.15 for its offsets and counts.

On disk (``F`` frames, ``B`` = max_batches, ``E`` elements)::

    run.zarr/
      zarr.json          group; attributes: format, format_version, scene_hash, config_hash, seed,
                         n_frames, n_elements, frame_numbers, max_batches, record_layout, complete
      batch/             (F, B, 5) u64, chunk (1, 1, 5), keys "c.f.b.0": [DONE_MAGIC, photon_start,
                         photons_emitted, n_records, digest]; a chunk exists <=> the batch is done
      counts/            (F, B, 4, E) u32, chunk (1, 1, 4, E): hits of batches 0..b (running sum)
                         per category indirect-even, indirect-odd, direct-even, direct-odd
      source/            (F,) i32, one chunk, -1 or the frame whose photons frame f reuses
      frames/<f>/        group per frame, made by the coordinator
        <b>/             made by the writer of (f, b) and by nobody else
          key (n,) u32   bary (n, 2) u16   energy (n, 3) f32   records sorted by element
          offsets (E+1,) i64   records of element e are [offsets[e], offsets[e+1])

Why this layout. Record counts per batch are unknown until traced and vary 2x per doubling
(§5.2.3), so each batch gets its own exactly-sized arrays, created by its writer under
``frames/<f>/<b>/``: in zarr v3 that writes only metadata inside the batch's own prefix
(parents exist), so no shared metadata and no resize. A preallocated (frame, capacity) layout
would need a capacity guess and coordinator resizes. The small fixed-size tables (batch, counts,
source) are made by the coordinator in :meth:`PhotonStore.create`; a chunk of them belongs to
exactly one (frame, batch), so concurrent writers never share a chunk (zarr 3 has no locks).
Counts are running sums so the frames x elements table is one chunk read per frame (300 x 45,000
in well under a second) rather than one per batch.

Atomicity and idempotence. LocalStore writes every chunk as temp file + rename, so a chunk is
whole or absent. A writer writes records, offsets and counts first and the ``batch`` chunk last;
that chunk is the done marker, so a killed writer leaves a batch that is not done, which a rerun
rewrites. Records are sorted into a total order (element, key, b1, b2, energy bits), so the
bytes do not depend on input order, and a rerun writes identical bytes over identical chunks
(existing arrays are reused, never deleted, so a duplicate task cannot expose a done batch with
missing chunks). Writing a batch that is already done only compares digests. Batch b needs batch
b-1 done and starts at its photon end, so done batches are a prefix 0..k-1 and batch b never
changes once written. ``file://`` URLs map to LocalStore for these guarantees (fsspec's local
filesystem neither renames atomically nor makes parent directories); other fsspec URLs rely on
the object store writing each object whole. A killed writer may leave ``*.partial`` temp files,
which zarr never reads.

Modules: ``records`` (the record, validation, total order; pure NumPy), ``photon_store`` (zarr).
"""
from .photon_store import (BATCH_FIELDS, DONE_MAGIC, FORMAT, FORMAT_VERSION, RECORD_CHUNK,
                           PhotonStore)
from .records import (BARY_SCALE, CATEGORIES, DIRECT_BIT, ELEMENT_BITS, ELEMENT_MASK, PARITY_BIT,
                      RECORD_BYTES, FrameRecords, pack_key, records_digest, sort_records)

__all__ = ["BARY_SCALE", "BATCH_FIELDS", "CATEGORIES", "DIRECT_BIT", "DONE_MAGIC", "ELEMENT_BITS",
           "ELEMENT_MASK", "FORMAT", "FORMAT_VERSION", "PARITY_BIT", "RECORD_BYTES",
           "RECORD_CHUNK", "FrameRecords", "PhotonStore", "pack_key", "records_digest",
           "sort_records"]
