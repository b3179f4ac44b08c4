"""``--animation``: a file's alternative clips (tests/scene/test_animation.py ``_clips``) rendered by
name through ``loom render`` (synchronous scheduler, real store and files): the clip's frames,
its name in report.json and the report, and a store of one clip never reused for another."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths, read_exr
from pipeline.report.page import write_report
from tests.scene.test_animation import _clips

ARGS = ["--frames", "1-3", "--photons", "2000", "--fmax", "2", "--resolution", "32x24", "--spp", "1",
        "--scheduler", "synchronous", "--quiet"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clips")
    path, _ = _clips(tmp / "clips.glb")
    runs = {}
    for clip in ("idle", "jump"):
        out = tmp / clip
        result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--animation", clip, *ARGS])
        assert result.exit_code == 0, result.output
        runs[clip] = out
    return path, runs


def test_each_clip_renders_its_own_motion(rendered):
    _, runs = rendered
    idle, jump = (read_exr(frame_paths(runs[c], 3)[0])[0]["A"] for c in ("idle", "jump"))
    assert np.array_equal(read_exr(frame_paths(runs["idle"], 1)[0])[0]["A"],
                          read_exr(frame_paths(runs["jump"], 1)[0])[0]["A"])  # both clips start at rest
    assert not np.array_equal(idle, jump)  # by frame 3 the jump has lifted and turned the body


def test_the_report_names_the_clip_and_the_ones_left_out(rendered):
    _, runs = rendered
    report = json.loads((runs["jump"] / "report.json").read_text())
    assert report["animations"] == {"played": ["jump", "animation 2"], "left_out": ["idle"]}
    html = write_report(runs["jump"]).read_text()
    assert "jump, animation 2 (left out: idle, alternative clips)" in html


def test_a_store_of_one_clip_is_not_reused_for_another(rendered, tmp_path):
    path, runs = rendered
    before = sorted(p.name for p in runs["jump"].iterdir())
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(runs["jump"]), *ARGS])  # the default: idle
    assert result.exit_code == 2 and "loom: error:" in result.output
    assert "(another scene file, or another clip of it: --animation); never mixed" in result.output
    assert sorted(p.name for p in runs["jump"].iterdir()) == before
