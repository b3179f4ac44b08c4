"""`loom plan` + make: a make-driven farm render gives the frames `loom render` gives, resumes after
a kill anywhere in `make -j2`, answers `make -q`, and its recipes exit at once when done."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.frames.images import frame_paths
from pipeline.segments.records import read_records

CHEAP = {"pilot_photons": 2000, "n_frame_min": 1000, "n_frame_max": 16000, "d_thr": 0.45,
         "fmax_initial": 6, "fmax_step": 4, "fmax_cap": 10}
FIRST, LAST = 60, 80
LOOM = [sys.executable, "-m", "pipeline"]


def _run(*args, check=True, **kw):
    result = subprocess.run([*map(str, args)], capture_output=True, text=True, **kw)
    if check:
        assert result.returncode == 0, result.stdout + result.stderr
    return result


def _options(out, config):
    return ["--frames", f"{FIRST}-{LAST}", "--out", out, "--resolution", "48x36", "--spp", "1", "--config", config]


def _frames(out):
    return {f: tuple(p.read_bytes() for p in frame_paths(out, f)) for f in range(FIRST, LAST + 1)}


def _make(out, *args, **kw):
    return _run("make", "-s", "-C", out, f"LOOM={sys.executable} -m pipeline", *args, **kw)


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("farm")
    scene = tmp / "room.glb"
    _run(*LOOM, "scene", "room", "-o", scene)
    config = tmp / "cheap.json"
    config.write_text(json.dumps(CHEAP))
    ref = tmp / "ref"
    _run(*LOOM, "render", scene, *_options(ref, config), "--scheduler", "synchronous", "--quiet")
    return tmp, scene, config, ref


def test_plan_and_make_give_the_frames_of_loom_render(room):
    tmp, scene, config, ref = room
    out = tmp / "farm"
    said = _run(*LOOM, "plan", scene, *_options(out, config)).stdout
    assert "Makefile" in said and (out / "Makefile").is_file()
    assert _make(out, "-q", check=False).returncode != 0  # not done yet
    _make(out, "-j2")
    assert _make(out, "-q", check=False).returncode == 0
    assert _frames(out) == _frames(ref)
    assert [r.without_times() for r in read_records(out)] == [r.without_times() for r in read_records(ref)]
    assert (out / "preview.mp4").is_file() and len(read_records(out)) >= 2
    # A recipe whose outputs are there and valid exits at once, saying so
    again = _run(*LOOM, "farm", "reconstruct", out, "0", "0").stdout
    assert "already reconstructed" in again


def test_fixed_settings_trace_in_shoot_targets_that_make_runs_side_by_side(room):
    """The farm's store keeps its hit records (--keep-records), the reference's does not: the same bits."""
    tmp, scene, config, _ = room
    fixed = ["--photons", "3000", "--fmax", "6"]
    ref, out = tmp / "fixed-ref", tmp / "fixed-farm"
    _run(*LOOM, "render", scene, *_options(ref, config), *fixed, "--scheduler", "synchronous", "--quiet")
    _run(*LOOM, "plan", scene, *_options(out, config), *fixed, "--keep-records")  # the farm keeps records
    rules = {line.split(":")[0]: line.split(":")[1].split() for line in (out / "Makefile").read_text().splitlines()
             if line.startswith(".farm/")}
    shoots = sorted(t for t in rules if "shoot-" in t)
    assert len(shoots) == 2 and all(rules[t] == [] for t in shoots)  # 21 frames: chunks of 16 and 5
    assert rules[".farm/decide-000.ok"] == shoots
    _make(out, "-j2")
    assert _frames(out) == _frames(ref)
    assert [r.without_times() for r in read_records(out)] == [r.without_times() for r in read_records(ref)]
    assert "already traced" in _run(*LOOM, "farm", "shoot", out, "0", "1").stdout
    assert "frames 76-80" in (out / ".farm" / "shoot-000-01.ok").read_text()
    assert any((out / "photons.zarr" / "frames").rglob("c.0.0")) and not (ref / "photons.zarr" / "frames").exists()


def test_a_killed_make_resumes_to_the_same_frames(room):
    tmp, scene, config, ref = room
    out = tmp / "killed"
    _run(*LOOM, "plan", scene, *_options(out, config))
    proc = subprocess.Popen(["make", "-s", "-C", str(out), "-j2", f"LOOM={sys.executable} -m pipeline"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if (out / ".farm" / "decide-001.ok").exists():  # killed while frames are being made
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.02)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "make finished before it could be killed"
    _make(out, "-j2")
    assert _frames(out) == _frames(ref)
    assert not list(out.rglob("*.partial*"))


def test_make_k_goes_on_past_a_failed_target_and_a_rerun_finishes(room, tmp_path):
    tmp, scene, config, ref = room
    out = tmp / "keep-going"
    _run(*LOOM, "plan", scene, *_options(out, config))
    # A recipe wrapper that fails the first segment's composites and runs every other recipe
    wrapper = tmp_path / "loom.sh"
    wrapper.write_text('case "$*" in *"farm frames "*" 0 0") echo "failing on purpose" >&2; exit 1;; esac\n'
                       f'exec {sys.executable} -m pipeline "$@"\n')
    failed = _run("make", "-s", "-k", "-C", out, f"LOOM=sh {wrapper}", check=False)
    assert failed.returncode != 0 and "failing on purpose" in failed.stderr
    stamps = {p.name for p in (out / ".farm").glob("*.ok")}
    assert "frames-000-00.ok" not in stamps and "done-000.ok" not in stamps and "finish.ok" not in stamps
    assert "frames-001-00.ok" in stamps  # made after the failure: it does not depend on it
    first = read_records(out)[0]
    assert not any(frame_paths(out, f)[0].exists() for f in range(first.start, first.end + 1))
    assert frame_paths(out, first.end + 1)[0].exists()
    _make(out)  # the rerun does what is missing
    assert _make(out, "-q", check=False).returncode == 0
    assert _frames(out) == _frames(ref)


def test_make_render_takes_a_built_in_scene_by_name(tmp_path):
    """The top-level `make render SCENE=cornell ...` writes the built-in scene into OUT, plans and
    makes it: the frames of `loom render` with the same settings; an unknown name is one line."""
    root = Path(__file__).resolve().parents[2]
    opts = "--resolution 32x24 --spp 1 --photons 2000 --fmax 4"
    out = tmp_path / "c"
    _run("make", "-s", "-C", root, "render", "SCENE=cornell", "FRAMES=1-3", f"OUT={out}", "JOBS=2", f"OPTS={opts}",
         f"LOOM={sys.executable} -m pipeline")
    assert (out / "cornell.glb").is_file() and _make(out, "-q", check=False).returncode == 0
    ref = tmp_path / "ref"
    _run(*LOOM, "render", out / "cornell.glb", "--frames", "1-3", "--out", ref, *opts.split(), "--quiet")
    for f in (1, 2, 3):
        assert [p.read_bytes() for p in frame_paths(out, f)] == [p.read_bytes() for p in frame_paths(ref, f)]
    bad = _run("make", "-s", "-C", root, "render", "SCENE=nosuch", f"OUT={tmp_path / 'x'}",
               f"LOOM={sys.executable} -m pipeline", check=False)
    assert bad.returncode != 0 and "unknown built-in scene 'nosuch'" in bad.stderr
    assert not (tmp_path / "x").exists()


def test_bad_plan_input_is_one_line(room, tmp_path):
    tmp, scene, config, _ = room
    result = _run(*LOOM, "farm", "decide", tmp_path / "nothing", "0", check=False)
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0 and "loom plan" in result.stderr
    result = _run(*LOOM, "plan", tmp_path / "missing.glb", "--out", tmp_path / "o", check=False)
    assert result.returncode == 2 and not (tmp_path / "o").exists()


def test_a_recipe_with_a_changed_or_missing_scene_is_one_line(room, tmp_path):
    tmp, scene, config, _ = room
    mine = tmp_path / "scene.glb"
    mine.write_bytes(scene.read_bytes())
    out = tmp_path / "plan"
    _run(*LOOM, "plan", mine, *_options(out, config))
    _run(*LOOM, "scene", "cornell", "-o", mine)  # another scene at the same path
    changed = _run(*LOOM, "farm", "decide", out, "0", check=False)
    mine.unlink()
    missing = _run(*LOOM, "farm", "decide", out, "0", check=False)
    for result, reason in ((changed, "changed"), (missing, "no such file")):
        assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
        assert str(mine) in result.stderr and reason in result.stderr
    assert not (out / "segments").exists()  # nothing half-written


def test_a_recipe_with_another_runs_store_or_an_unwritable_one_is_one_line(room, tmp_path):
    import shutil

    tmp, scene, config, _ = room
    out, other = tmp_path / "plan", tmp_path / "other"
    _run(*LOOM, "plan", scene, *_options(out, config))
    cornell = tmp_path / "cornell.glb"
    _run(*LOOM, "scene", "cornell", "-o", cornell)
    _run(*LOOM, "plan", cornell, "--frames", "1-4", "--out", other, "--config", config)
    shutil.rmtree(out / "photons.zarr")
    shutil.copytree(other / "photons.zarr", out / "photons.zarr")  # another run's store
    swapped = _run(*LOOM, "farm", "decide", out, "0", check=False)
    assert swapped.returncode == 2 and len(swapped.stderr.strip().splitlines()) == 1
    assert "photons.zarr" in swapped.stderr and "scene" in swapped.stderr
    # A store a worker cannot write into: where its batches go is a file
    _run(*LOOM, "plan", scene, *_options(tmp_path / "third", config))
    (tmp_path / "third" / "photons.zarr" / "batch").write_text("not a folder")
    broken = _run(*LOOM, "farm", "decide", tmp_path / "third", "0", check=False)
    assert broken.returncode == 2 and len(broken.stderr.strip().splitlines()) == 1, broken.stderr
    assert "photons.zarr" in broken.stderr and "cannot write" in broken.stderr
