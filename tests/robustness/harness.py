"""Run many ``loom`` command lines in one child process, each under a time limit, the whole under a
memory limit, and report how each ended.

``python -m tests.robustness.harness JOBS.json`` reads a list of ``{"name", "argv", "timeout"}``
and writes one JSON line per job to stdout: the exit code, the stderr lines, the traceback if the
command raised one, ``hang`` if it ran past its timeout (SIGALRM), and at the end the process's
peak resident memory (:func:`peak_resident_bytes`), which bounds every job's peak. ``RLIMIT_AS`` (the address-space
limit, given in bytes by ``--address-space``) keeps a regression from taking the machine down: an
allocation beyond it fails as a MemoryError traceback, which the tests count as a failure.
"""
from __future__ import annotations

import contextlib
import io
import json
import resource
import signal
import sys
import time
import traceback


class _Hang(BaseException):
    """Raised by SIGALRM: the job ran past its timeout (a BaseException, so no except catches it)."""


def _alarm(_signum, _frame):
    raise _Hang()


def run(jobs: list[dict]) -> list[dict]:
    from pipeline.cli import main

    signal.signal(signal.SIGALRM, _alarm)
    results = []
    for job in jobs:
        err = io.StringIO()
        out = io.StringIO()
        result = {"name": job["name"], "code": None, "traceback": None, "hang": False}
        t0 = time.monotonic()
        signal.alarm(int(job["timeout"]))
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
                main(job["argv"], prog_name="loom")
            result["code"] = 0
        except SystemExit as exit_:
            result["code"] = exit_.code if isinstance(exit_.code, int) else 1
        except _Hang:
            result["hang"] = True
        except BaseException:  # a bug: the traceback is the finding
            result["traceback"] = traceback.format_exc()
        finally:
            signal.alarm(0)
        result["seconds"] = round(time.monotonic() - t0, 3)
        result["stderr"] = [line for line in err.getvalue().splitlines() if line.strip()]
        result["stdout"] = out.getvalue()[-2000:]
        results.append(result)
    return results


def peak_resident_bytes() -> int:
    """This process's peak resident memory: ``VmHWM`` of /proc/self/status, which starts afresh at
    exec. Not ``ru_maxrss``: Linux keeps that across fork and exec, so a harness started from a
    pytest process that once held 1.3 GB reported 1.3 GB for a batch whose own peak was 61 MB."""
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024  # kB
    raise RuntimeError("no VmHWM in /proc/self/status")


def main() -> None:
    args = sys.argv[1:]
    if args[0] == "--address-space":
        limit = int(args[1])
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        args = args[2:]
    with open(args[0], encoding="utf-8") as fh:
        jobs = json.load(fh)
    for result in run(jobs):
        print(json.dumps(result), flush=True)
    print(json.dumps({"peak_bytes": peak_resident_bytes()}), flush=True)


if __name__ == "__main__":
    main()
