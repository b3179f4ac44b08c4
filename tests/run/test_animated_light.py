"""A lamp animated through KHR_animation_pointer (tests/scene/test_animation.py ``_pointer_lamp``:
10 W/sr white at t = 0, 40 W/sr of colour (1, 0.5, 0.25) at t = 1 s) rendered by ``loom render``
(synchronous scheduler, real store and files): the direct light of frame 31 is the lamp's radiant
intensity times that of frame 1, channel by channel, (4, 2, 1), as a point light's irradiance
I cos / r^2 is linear in I; and loom info names the animated light. An area light switched on by
its material's emission strength."""
from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths, read_exr
from tests.conftest import basic_builder
from tests.scene.test_animation import CUBE, CUBE_FACES, _pointer_lamp


def test_the_direct_light_follows_the_lamp(tmp_path):
    path = _pointer_lamp(tmp_path / "lamp.glb")
    info = CliRunner().invoke(main, ["info", str(path)])
    assert info.exit_code == 0 and "animated   0 nodes; 1 lights: lamp [color, intensity]" in info.output
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1,31", "--photons", "2000",
                                       "--temporal", "off", "--resolution", "32x24", "--spp", "1",
                                       "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    first, last = (read_exr(frame_paths(out, f)[0])[0] for f in (1, 31))
    # pixels on the floor in both frames (a pixel's one jittered sample moves from frame to frame, so
    # the floor's edge pixels differ, and inside it each pixel's irradiance moves by well under 1 %)
    lit = (first["direct.R"] > 0) & (last["direct.R"] > 0)
    assert lit.sum() > 50
    for channel, ratio in zip("RGB", (4.0, 2.0, 1.0)):
        change = last[f"direct.{channel}"][lit] / first[f"direct.{channel}"][lit]
        assert abs(np.median(change) / ratio - 1) < 0.01, channel


def test_a_panel_that_switches_on_renders_dark_frames_then_light(tmp_path):
    # The only light is a panel whose emission strength steps 0 -> 3 at 0.5 s (frame 16): the frames
    # before trace photons that carry nothing and are black, with the guided defaults
    b = basic_builder(light=False)
    panel = b.add_material("panel", (0.5, 0.5, 0.5), emissive=(1.0, 0.5, 0.5), emissive_strength=0.0)
    b.add_node("panel", b.add_mesh("panel", CUBE, CUBE_FACES, material=panel), translation=(0, 1, 0))
    b.add_pointer_animation("switch", f"/materials/{panel}/extensions/KHR_materials_emissive_strength/"
                            "emissiveStrength", [0, 0.5], [0.0, 3.0], "STEP")
    path = b.write(tmp_path / "switch.glb")
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--resolution", "32x24", "--spp", "1",
                                       "--scheduler", "synchronous", "--quiet"])
    assert result.exit_code == 0, result.output
    beauty = [read_exr(frame_paths(out, f)[0])[0]["R"] for f in range(1, 17)]
    assert all(not b.any() for b in beauty[:15]) and beauty[15].mean() > 0.01
