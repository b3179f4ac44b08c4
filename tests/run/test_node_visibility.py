"""A box shown and hidden through KHR_node_visibility (tests/scene/test_visibility.py ``cubes``),
rendered by ``loom render`` (synchronous scheduler, real store and files): while hidden it casts no
shadow and is seen nowhere, its frame's direct light that of the same file with the box hidden
throughout, to the bit; while shown it covers pixels and shadows the floor."""
from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths, read_exr
from tests.scene.test_visibility import cubes


def _direct(path, out):
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1,3", "--photons", "2000",
                                       "--temporal", "off", "--resolution", "48x36", "--spp", "1",
                                       "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    return [np.stack([read_exr(frame_paths(out, f)[0])[0][f"direct.{c}"] for c in "RGB"], -1) for f in (1, 3)]


def test_a_hidden_box_is_neither_seen_nor_casts_a_shadow(tmp_path):
    shown, hidden = _direct(cubes(tmp_path / "blink.glb"), tmp_path / "blink")
    never = _direct(cubes(tmp_path / "never.glb", blink=(False,)), tmp_path / "never")
    assert np.array_equal(hidden, never[1])  # the same frame, so the same camera samples
    differs = np.any(shown != hidden, axis=-1)
    assert differs.sum() > 20  # the box, blue, and its shadow
    box = differs & (shown[..., 2] > 2 * shown[..., 0])
    assert box.sum() > 10 and np.all(hidden[box][:, 2] < 1.5 * hidden[box][:, 0])
