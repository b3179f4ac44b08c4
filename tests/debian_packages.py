"""Debian packages a test needs, installed with apt-get when missing: the test setup of a fresh
Debian machine (as ``make setup`` installs PoCL), shared by tests/report/browser.py (Chromium) and
tests/farm/docker_engine.py (Docker, compose, debootstrap)."""
from __future__ import annotations

import os
import subprocess


def apt_install(*packages: str) -> None:
    """``apt-get update`` then ``apt-get install -y`` of ``packages``, non-interactively."""
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    subprocess.run(["apt-get", "update", "-qq"], check=True, env=env, stdout=subprocess.DEVNULL)
    subprocess.run(["apt-get", "install", "-y", "-qq", *packages], check=True, env=env, stdout=subprocess.DEVNULL)
