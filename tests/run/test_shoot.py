"""`loom shoot`: camera-only sharing, appending batches, resume after a kill, refusals, bad input."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.config import PhotonConfig
from pipeline.errors import LoomError
from pipeline.run.shoot import plan, shoot, tasks
from pipeline.scene import read_scene
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore
from tests.run.shoot_helpers import store_fingerprint


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    d = tmp_path_factory.mktemp("scenes")
    return {name: str(write_builtin(name, d / f"{name}.glb")) for name in ("cornell", "static", "room")}


@pytest.fixture(scope="module")
def reference(scenes, tmp_path_factory):
    """An uninterrupted synchronous shoot of cornell frames 1-12."""
    url = str(tmp_path_factory.mktemp("ref") / "ref.zarr")
    shoot(plan(read_scene(scenes["cornell"]), "1-12", 6000, PhotonConfig()), url,
          scheduler="synchronous", progress=False, keep_records=True)
    return url


def test_camera_only_frames_share_one_photon_set(scenes, tmp_path):
    url = str(tmp_path / "s.zarr")
    summary = shoot(plan(read_scene(scenes["static"]), None, 4000, PhotonConfig()), url,
                    scheduler="synchronous", progress=False, keep_records=True)
    assert summary["traced_frames"] == 1 and summary["tasks"] == 1
    store = PhotonStore.open(url)
    assert [store.source_frame(f) for f in range(store.n_frames)] == [0] * store.n_frames
    a, b = store.read_frame(0), store.read_frame(store.n_frames - 1)
    assert a.key.tobytes() == b.key.tobytes() and len(a.key) > 1000


def test_more_photons_append_a_batch_without_touching_the_first(scenes, reference, tmp_path):
    url = str(tmp_path / "grow.zarr")
    shoot(plan(read_scene(scenes["cornell"]), "1-12", 6000, PhotonConfig()), url,
          scheduler="synchronous", progress=False, keep_records=True)
    assert store_fingerprint(url) == store_fingerprint(reference)
    before = PhotonStore.open(url).read_frame(3, batches=[0])
    summary = shoot(plan(read_scene(scenes["cornell"]), "4", 12000, PhotonConfig()), url,
                    scheduler="synchronous", progress=False, keep_records=True)
    assert summary["tasks"] == 1 and summary["photons"] == 6000
    store = PhotonStore.open(url)
    assert store.done_batches(3) == [0, 1] and store.photons_emitted(3) == 12000
    after = store.read_frame(3, batches=[0])
    assert after.key.tobytes() == before.key.tobytes() and after.energy.tobytes() == before.energy.tobytes()
    assert store.batch_info(3, 1)["photon_start"] == 6000


def test_rerun_skips_done_batches(scenes, reference):
    summary = shoot(plan(read_scene(scenes["cornell"]), "1-12", 6000, PhotonConfig()), reference,
                    scheduler="synchronous", progress=False, keep_records=True)
    assert summary["tasks"] == 0


def test_resume_after_kill_matches_uninterrupted_run(scenes, tmp_path):
    # 30 frames of 40,000 photons: long enough that the writer is still mid-run when killed
    url, reference = str(tmp_path / "killed.zarr"), str(tmp_path / "whole.zarr")
    cmd = [sys.executable, "-m", "pipeline", "shoot", scenes["cornell"], "--frames", "1-30",
           "--photons", "40000", "--store", url, "--scheduler", "synchronous", "--quiet"]
    subprocess.run(cmd[:-5] + ["--store", reference] + cmd[-3:], check=True, capture_output=True)
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    done = 0
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            done = sum(len(PhotonStore.open(url).done_batches(f)) for f in range(30))
        except LoomError:
            done = 0
        if done >= 3:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the shoot finished before it could be killed"
    assert 3 <= done < 30
    result = subprocess.run(cmd, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "already done" in result.stdout
    assert store_fingerprint(url) == store_fingerprint(reference)


def test_store_of_another_scene_or_config_is_refused(scenes, reference):
    runner = CliRunner()
    other_scene = runner.invoke(main, ["shoot", scenes["static"], "--photons", "100", "--store", reference,
                                       "--scheduler", "synchronous"])
    assert other_scene.exit_code == 2 and "scene_hash" in other_scene.output
    assert len(other_scene.output.strip().splitlines()) == 1
    other_config = runner.invoke(main, ["shoot", scenes["cornell"], "--photons", "100", "--store", reference,
                                        "--element-size", "0.3", "--scheduler", "synchronous"])
    assert other_config.exit_code == 2 and "config_hash" in other_config.output


@pytest.mark.parametrize("args, words", [
    (["--photons", "0"], "--photons"),
    (["--photons", "-5"], "--photons"),
    (["--frames", "1-999"], "outside the timeline"),
    (["--frames", "x-y"], "cannot parse"),
])
def test_bad_input_writes_nothing(scenes, tmp_path, args, words):
    url = tmp_path / "never.zarr"
    result = CliRunner().invoke(main, ["shoot", scenes["cornell"], "--store", str(url),
                                       "--scheduler", "synchronous", *args])
    assert result.exit_code == 2 and words in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not url.exists()


def test_unwritable_store_path(scenes, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    for target in (blocker, blocker / "sub.zarr"):
        result = CliRunner().invoke(main, ["shoot", scenes["cornell"], "--store", str(target),
                                           "--scheduler", "synchronous"])
        assert result.exit_code == 2 and str(blocker) in result.output
        assert len(result.output.strip().splitlines()) == 1
    assert blocker.read_text() == "not a directory"


def test_file_url_store(scenes, reference, tmp_path):
    url = "file://" + str(tmp_path / "url.zarr")
    shoot(plan(read_scene(scenes["cornell"]), "1-12", 6000, PhotonConfig()), url,
          scheduler="synchronous", progress=False, keep_records=True)
    assert store_fingerprint(url) == store_fingerprint(reference)


def test_photons_fill_the_room_frames(scenes, tmp_path):
    """A ROOM frame's records land on many elements and the count table agrees with the records."""
    url = str(tmp_path / "room.zarr")
    shoot(plan(read_scene(scenes["room"]), "60", 5000, PhotonConfig()), url,
          scheduler="synchronous", progress=False, keep_records=True)
    store = PhotonStore.open(url)
    recs = store.read_frame(59)
    counts = store.counts("all", frames=[59])[0]
    assert counts.sum() == len(recs.key)
    assert np.count_nonzero(counts) > 0.2 * store.n_elements


def test_two_stores_never_share_a_task_key(scenes, tmp_path):
    # A key the cluster still holds returns the earlier task's result without running it, so the
    # same batches shot into two stores must have different keys (the second store stayed empty)
    p = plan(read_scene(scenes["cornell"]), "1-2", 2_000, PhotonConfig())
    keys = {}
    for name in ("a", "b"):
        url = str(tmp_path / f"{name}.zarr")
        shoot(plan(read_scene(scenes["cornell"]), "1-2", 1_000, PhotonConfig()), url,
              scheduler="synchronous", progress=False)
        keys[name] = [k for k, _ in tasks(p, PhotonStore.open(url), url)]  # the second batch of each frame
    assert len(keys["a"]) == len(keys["b"]) == 2 and not set(keys["a"]) & set(keys["b"])
