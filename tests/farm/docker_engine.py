"""A real Docker engine for the container test (Debian's ``docker.io`` and ``docker-compose``).

``ensure_engine`` installs the packages with apt-get when they are missing and starts ``dockerd``
when no daemon answers (the test setup of a fresh Debian machine, as tests/report/browser.py does
for Chromium). ``base_image`` answers docker/Dockerfile's ``BASE``: Docker Hub's
``python:3.11-slim-bookworm`` when it is here or can be pulled, otherwise a stand-in built from
Debian bookworm with debootstrap (Debian's Python 3.11 in a venv first on the PATH, as the official
image has its own) and this machine's CA bundle, because the package registries are reached through
a proxy that re-signs TLS: pip inside a container would refuse PyPI without it.
"""
from __future__ import annotations

import shlex
import shutil
import subprocess
import time
from pathlib import Path

from tests.debian_packages import apt_install

OFFICIAL_BASE = "python:3.11-slim-bookworm"
STAND_IN = "photonloom-test-base:bookworm"
MIRROR = "http://deb.debian.org/debian"
CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")

STAND_IN_DOCKERFILE = """\
FROM photonloom-test-rootfs:bookworm
COPY ca-certificates.crt /etc/ssl/certs/ca-certificates.crt
RUN python3 -m venv /usr/local/python
ENV PATH=/usr/local/python/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \\
    SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt PIP_CERT=/etc/ssl/certs/ca-certificates.crt LANG=C.UTF-8
LABEL org.photonloom.stand-in-for=python:3.11-slim-bookworm
CMD ["python3"]
"""


def _answers() -> bool:
    return subprocess.run(["docker", "info"], capture_output=True).returncode == 0


def compose_command() -> list[str]:
    """Compose v2 (``docker compose``) where installed, else v1 (``docker-compose``)."""
    if subprocess.run(["docker", "compose", "version"], capture_output=True).returncode == 0:
        return ["docker", "compose"]
    return ["docker-compose"]


def ensure_engine(log: Path) -> None:
    """A Docker daemon that answers, with compose; installed and started when missing."""
    missing = [pkg for pkg, exe in (("docker.io", "dockerd"), ("docker-compose", "docker-compose"),
                                    ("debootstrap", "debootstrap")) if shutil.which(exe) is None]
    if missing:
        apt_install(*missing)
    if _answers():
        return
    # Started by a shell that exits at once: the daemon outlives the test, nothing waits for it
    subprocess.run(f"setsid dockerd >> {shlex.quote(str(log))} 2>&1 &", shell=True, check=True)
    deadline = time.monotonic() + 60
    while not _answers():
        if time.monotonic() > deadline:
            raise RuntimeError(f"dockerd did not answer within 60 s (its log: {log})")
        time.sleep(0.5)


def _present(image: str) -> bool:
    return subprocess.run(["docker", "image", "inspect", image], capture_output=True).returncode == 0


def base_image(work: Path) -> str:
    """The image to build docker/Dockerfile FROM (see the module docstring)."""
    if _present(OFFICIAL_BASE):
        return OFFICIAL_BASE
    try:
        if subprocess.run(["docker", "pull", OFFICIAL_BASE], capture_output=True, timeout=120).returncode == 0:
            return OFFICIAL_BASE
    except subprocess.TimeoutExpired:
        pass
    if _present(STAND_IN):
        return STAND_IN
    rootfs = work / "rootfs"
    subprocess.run(["debootstrap", "--variant=minbase", "--include=python3,python3-venv,ca-certificates",
                    "bookworm", str(rootfs), MIRROR], check=True, capture_output=True)
    subprocess.run(f"tar -C {shlex.quote(str(rootfs))} -c . | docker import - photonloom-test-rootfs:bookworm",
                   shell=True, check=True, capture_output=True)
    shutil.rmtree(rootfs, ignore_errors=True)
    context = work / "base"
    context.mkdir()
    shutil.copy(CA_BUNDLE, context / "ca-certificates.crt")
    (context / "Dockerfile").write_text(STAND_IN_DOCKERFILE)
    subprocess.run(["docker", "build", "-q", "-t", STAND_IN, str(context)], check=True, capture_output=True)
    return STAND_IN
