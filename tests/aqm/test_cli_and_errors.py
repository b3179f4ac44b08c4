"""Bad input gives one-line errors; ``loom aqm`` prints d_AQM and writes the Fig. 3d map; ``loom bench aqm`` runs."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
from aqm_data import SIZE, monte_carlo
from click.testing import CliRunner

from pipeline.aqm import Motion, aqm
from pipeline.cli import main
from pipeline.errors import LoomError


def write_exr(path, pixels: np.ndarray) -> str:
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], channels, oiio.FLOAT))
    assert out.write_image(pixels)
    out.close()
    return str(path)


def read_png(path) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    pixels = inp.read_image(oiio.UINT8)
    inp.close()
    return pixels


def with_value(image: np.ndarray, value: float) -> np.ndarray:
    bad = image.copy()
    bad[5, 7, 1] = value
    return bad


@pytest.fixture
def frames(shaded_scene):
    """A clean frame and a noisy one whose noise is visible in part of the image."""
    noisy = shaded_scene.copy()
    noisy[:, : SIZE // 2] = monte_carlo(shaded_scene[:, : SIZE // 2], 100, seed=5)
    return shaded_scene, noisy


@pytest.mark.parametrize("make_b,field", [
    (lambda a: a[:-1], "size"),
    (lambda a: with_value(a, np.nan), "pixels"),
    (lambda a: with_value(a, np.inf), "pixels"),
    (lambda a: with_value(a, -0.5), "luminance"),
])
def test_bad_input_is_one_line_error(shaded_scene, make_b, field):
    with pytest.raises(LoomError) as err:
        aqm(shaded_scene, make_b(shaded_scene), names=("a.exr", "b.exr"))
    assert err.value.field == field
    assert err.value.path == "b.exr"
    assert "\n" not in str(err.value)


def test_bad_flow_is_one_line_error(frames):
    a, b = frames
    with pytest.raises(LoomError) as err:
        aqm(a, b, motion=Motion(np.full((SIZE, SIZE), np.nan)))
    assert "\n" not in str(err.value)
    with pytest.raises(LoomError):
        aqm(a, b, motion=Motion(np.zeros((SIZE, SIZE - 1, 2))))
    with pytest.raises(LoomError, match="pursuit_gain: must lie in"):
        Motion(np.zeros((SIZE, SIZE, 2)), pursuit_gain=1.5)


@pytest.fixture
def exr_files(tmp_path, frames):
    a, b = frames
    return write_exr(tmp_path / "a.exr", a), write_exr(tmp_path / "b.exr", b)


def test_cli_prints_d_aqm_and_writes_red_over_grey_map(tmp_path, exr_files, frames):
    out = tmp_path / "map.png"
    result = CliRunner().invoke(main, ["aqm", *exr_files, "--map", str(out)])
    assert result.exit_code == 0, result.output
    expected = aqm(*frames).d_aqm
    assert f"d_AQM = {expected:.3f} %" in result.output
    picture = read_png(out)
    red = (picture[..., 0] == 255) & (picture[..., 1] == 0) & (picture[..., 2] == 0)
    grey = (picture[..., 0] == picture[..., 1]) & (picture[..., 1] == picture[..., 2])
    assert np.all(red | grey)
    assert 100 * red.mean() == pytest.approx(expected)
    assert red[:, : SIZE // 2].any() and not red[:, SIZE // 2 + 16:].any()  # only the noisy half


def test_cli_flow_file_in_pixels_per_frame(tmp_path, exr_files, frames):
    flow = np.zeros((SIZE, SIZE, 3))
    flow[..., 0] = 4.0  # px/frame
    path = write_exr(tmp_path / "flow.exr", flow)
    args = ["aqm", *exr_files, "--flow", path, "--flow-units", "px/frame", "--fps", "25", "--pursuit-gain", "0"]
    moving = CliRunner().invoke(main, args)
    still = CliRunner().invoke(main, ["aqm", *exr_files])
    assert moving.exit_code == 0, moving.output
    d_moving = float(moving.output.split("d_AQM = ")[1].split()[0])
    d_still = float(still.output.split("d_AQM = ")[1].split()[0])
    assert d_moving < d_still


@pytest.mark.parametrize("problem", ["size", "nan", "missing", "garbage"])
def test_cli_bad_input_exits_with_one_line(tmp_path, exr_files, shaded_scene, problem):
    a, _ = exr_files
    b = str(tmp_path / "b_bad.exr")
    if problem == "size":
        write_exr(b, shaded_scene[:100])
    elif problem == "nan":
        write_exr(b, with_value(shaded_scene, np.nan))
    elif problem == "garbage":
        (tmp_path / "b_bad.exr").write_bytes(b"not an image")
    result = CliRunner().invoke(main, ["aqm", a, b])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines() if hasattr(result, "stderr") else result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("loom: error: ") and "b_bad.exr" in lines[0]


def test_bench_reports_both_variants():
    result = CliRunner().invoke(main, ["bench", "aqm", "--repeat", "1"])
    assert result.exit_code == 0, result.output
    assert "no flow" in result.output and "with flow" in result.output and "s/pair" in result.output
