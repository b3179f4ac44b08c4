"""``loom render`` end to end (synchronous scheduler, real files): layers, metadata, PNG, video,
reruns, determinism and bad input."""
from __future__ import annotations

import json

import imageio_ffmpeg
import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.config import RenderConfig
from pipeline.frames.images import EXR_CHANNELS, frame_paths, read_exr
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.scene import read_scene
from tests.frames.scenes import plane_scene

SMALL = RenderSettings(width=32, height=24, spp=1)


def _render(scene, out, frames="1-3", keep_records=False):
    return render(RenderRequest(scene_path=scene, frames=frames, out_dir=out, settings=SMALL, n_photons=3000,
                                keep_records=keep_records), scheduler="synchronous")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Three frames of a plane under a point light, with a panning camera."""
    tmp = tmp_path_factory.mktemp("render")
    scene = plane_scene(tmp / "plane.glb", frames=3)
    report = _render(scene, tmp / "out")
    return scene, tmp / "out", report


def test_single_plane_under_one_light_has_no_indirect_light(rendered):
    _, out, _ = rendered
    channels, _ = read_exr(frame_paths(out, 2)[0])
    assert all(np.all(channels[f"indirect.{c}"] == 0) for c in "RGB")
    assert channels["direct.G"].max() > 0


def test_exr_has_layers_metadata_and_float_pixels(rendered):
    scene, out, report = rendered
    exr = frame_paths(out, 1)[0]
    channels, meta = read_exr(exr)
    assert set(channels) == set(EXR_CHANNELS)
    np.testing.assert_allclose(channels["R"], channels["direct.R"] + channels["indirect.R"], rtol=1e-6)
    assert np.all(channels["A"] == 1)
    assert meta["scene"] == "plane.glb" and meta["frame"] == 1 and meta["camera"] == "cam"
    assert meta["photons"] == 3000 and meta["config_hash"] == RenderConfig().hash
    assert meta["render_hash"] == report["render_hash"]
    spec = oiio.ImageInput.open(str(exr)).spec()
    assert spec.format == oiio.FLOAT and spec.get_string_attribute("compression") == "zip"


def test_png_is_8bit_srgb_and_video_has_one_frame_per_frame(rendered):
    _, out, report = rendered
    buf = oiio.ImageBuf(str(frame_paths(out, 3)[1]))
    spec = buf.spec()
    assert spec.format == oiio.UINT8 and spec.nchannels == 3 and (spec.width, spec.height) == (32, 24)
    assert spec.get_string_attribute("oiio:ColorSpace") == "srgb_rec709_scene"
    assert buf.get_pixels(oiio.UINT8).max() > 0
    n_frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out / "preview.mp4"))
    assert n_frames == 3
    saved = json.loads((out / "report.json").read_text())
    assert saved["frames"] == [1, 2, 3] and saved["rays"]["camera"] == 3 * 32 * 24
    assert saved["rays"]["reflection"] == saved["rays"]["area"] == 0  # not needed by the scene
    assert set(saved["rays_per_frame"]) == {"1", "2", "3"}


def test_rerun_skips_valid_frames_and_redoes_broken_ones(rendered, tmp_path):
    scene, out, _ = rendered
    exr2 = frame_paths(out, 2)[0]
    before = exr2.stat().st_mtime_ns
    frame_paths(out, 3)[1].write_bytes(b"not a png")
    again = _render(scene, out)
    assert again["skipped"] == [1, 2] and again["rendered"] == [3]
    assert again["photon_batches_traced"] == 0
    assert exr2.stat().st_mtime_ns == before


def test_same_inputs_give_identical_frames(rendered, tmp_path):
    scene, out, _ = rendered
    _render(scene, tmp_path / "again")  # the same frames: adaptation is smoothed over them
    a, _ = read_exr(frame_paths(out, 2)[0])
    b, _ = read_exr(frame_paths(tmp_path / "again", 2)[0])
    assert all(np.array_equal(a[c], b[c]) for c in EXR_CHANNELS)
    png = [oiio.ImageBuf(str(frame_paths(d, 2)[1])).get_pixels(oiio.UINT8) for d in (out, tmp_path / "again")]
    assert np.array_equal(*png)


def _cli(*args):
    result = CliRunner().invoke(main, ["render", *map(str, args)])
    return result, result.stderr.strip().splitlines()


@pytest.mark.parametrize("bad", [
    ("--resolution", "0x480"), ("--resolution", "640x0"), ("--resolution", "wide"),
    ("--camera", "nosuchcamera"), ("--spp", "0"), ("--photons", "0"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, bad):
    scene = plane_scene(tmp_path / "s.glb")
    out = tmp_path / "out"
    result, lines = _cli(scene, "--out", out, "--scheduler", "synchronous", *bad)
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("loom: error:")
    assert not out.exists()


def test_output_path_that_is_a_file_is_refused(tmp_path):
    scene = plane_scene(tmp_path / "s.glb")
    target = tmp_path / "taken"
    target.write_text("keep me")
    result, lines = _cli(scene, "--out", target, "--scheduler", "synchronous")
    assert result.exit_code == 2 and len(lines) == 1 and "--out" in lines[0]
    assert target.read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.glb", "taken"]


def test_store_holds_each_frames_maps_from_its_own_photons(rendered):
    from pipeline.collection.estimators import vertex_irradiance
    from pipeline.scene import ElementMesh
    from pipeline.store import PhotonStore
    from pipeline.store.illumination import IlluminationMaps

    scene_path, out, _ = rendered
    kept = out.parent / "kept"  # the same render with its hit records, to sum them here
    _render(scene_path, kept, keep_records=True)
    scene = read_scene(scene_path)
    elements = ElementMesh.build(scene)
    assert IlluminationMaps.open(kept / "photons.zarr").read(1, "direct").tobytes() == \
        IlluminationMaps.open(out / "photons.zarr").read(1, "direct").tobytes()
    out = kept
    maps = IlluminationMaps.open(out / "photons.zarr")
    assert maps.n_vertices == elements.n_vertices and np.all(maps.adaptation()[:3] > 0)
    records = PhotonStore.open(out / "photons.zarr").read_frame(1)
    areas = elements.vertex_areas(scene.pose_frame(2))
    d = records.direct
    want = vertex_irradiance(records.element[d], records.b1[d], records.b2[d], records.energy[d],
                             elements, areas, records.photons_emitted)
    np.testing.assert_allclose(maps.read(1, "direct"), want, rtol=1e-6)
    assert want.max() > 0 and not maps.read(1, "indirect").any()


def test_every_option_for_a_renders_spp_defaults_to_render_settings():
    # One owner (docs/10-sampling.md §2): loom render, loom plan and the benchmarks that render as loom
    # render does read RenderSettings.spp; the CLI reads it only when an option's default is needed.
    import subprocess
    import sys

    import click

    from pipeline.benchmarks.error import Plan
    from pipeline.benchmarks.render import run as bench_render_run

    assert RenderSettings().spp == RenderSettings.spp == 8
    commands = {"render": ["render"], "plan": ["plan"], "bench error": ["bench", "error"],
                "bench render": ["bench", "render"]}
    for name, path in commands.items():
        command = main
        for part in path:
            command = command.commands[part]
        (spp,) = [p for p in command.params if p.name == "spp"]
        with click.Context(command) as ctx:
            assert spp.get_default(ctx) == RenderSettings.spp, name
        shown = CliRunner().invoke(main, [*path, "--help"], terminal_width=200).output
        assert f"[default: {RenderSettings.spp}]" in shown.split("--spp", 1)[1].split("\n  --", 1)[0], name
    assert Plan((1, 4), (1_000,), 2, (0.5,)).spp == RenderSettings.spp
    assert bench_render_run.__kwdefaults__["spp"] == RenderSettings.spp
    # starting the CLI does not import the renderer (about 0.3 s on every loom command)
    code = "import sys, pipeline.cli; print('pipeline.run.render' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() \
        == "False"
