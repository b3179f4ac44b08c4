"""Writing a file past the page cache (``O_DIRECT``), for objects written once and seldom read.

A batch's photon records are the store's truth but, once its summary is stored beside them
(pipeline/collection/batch_sums.py), nothing in a render reads them again. Written the usual way, every byte
first lands in a newly allocated page-cache page. On the build machines (Firecracker VMs whose
free memory the host reclaims, docs/13-cluster.md §5) a new page costs 3-33 us,
so a 1.8 MB ROOM batch took 12 ms of CPU to write; with ``O_DIRECT`` it takes 0.3 ms of CPU and
1-2 ms of wall time (the same 40 files each way, medians). On any machine it keeps a store of
gigabytes from pushing useful data out of the cache. A later read comes from the disk instead
of memory (about 6 ms for such a file), which only the rare readers of records pay.

``O_DIRECT`` wants the buffer, the file offset and the length aligned to the device's block:
the bytes are copied into a page-aligned buffer reused by the process, padded to
:data:`ALIGN`, and the file is cut back to its true length. Where the file system refuses
``O_DIRECT`` (tmpfs on older kernels, some network file systems: ``EINVAL``) the caller writes
the usual way; the bytes on disk are the same either way.
"""
from __future__ import annotations

import errno
import mmap
import os
import threading

ALIGN = 4096  # the largest logical block size of the disks we write to (512 or 4096)
_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_DIRECT", 0) | getattr(os, "O_CLOEXEC", 0)
_lock = threading.Lock()
_buffer: list[mmap.mmap] = []  # the process's aligned buffer, grown on demand


def supported() -> bool:
    """Whether this platform has ``O_DIRECT`` at all (Linux does; macOS does not)."""
    return hasattr(os, "O_DIRECT")


def write_new(path: str, data: bytes | memoryview) -> bool:
    """Create (or truncate) ``path`` to hold ``data``, bypassing the page cache.

    Returns False, leaving no file, where the file system refuses ``O_DIRECT``; other errors
    propagate (a partly written file is removed first)."""
    if not supported():
        return False
    n = len(data)
    size = max(ALIGN, -(-n // ALIGN) * ALIGN)
    try:
        fd = os.open(path, _FLAGS, 0o666)
    except OSError as e:
        if e.errno == errno.EINVAL:
            return False
        raise
    try:
        with _lock:
            if not _buffer or len(_buffer[0]) < size:
                _buffer[:] = [mmap.mmap(-1, size)]  # anonymous mappings are page-aligned
            buf = _buffer[0]
            buf[:n] = data
            buf[n:size] = bytes(size - n)
            view = memoryview(buf)[:size]
            try:
                done = 0
                while done < size:
                    done += os.write(fd, view[done:])
            finally:
                view.release()
        os.ftruncate(fd, n)
    except BaseException as e:
        os.close(fd)
        os.unlink(path)
        if isinstance(e, OSError) and e.errno == errno.EINVAL:  # refused at the first write, not at open
            return False
        raise
    os.close(fd)
    return True
