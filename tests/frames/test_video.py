"""``preview.mp4`` (pipeline/frames/images.write_video): ffmpeg decodes the PNGs itself; odd sizes are
padded to even ones, and a broken input fails with the path named and nothing left behind."""
from __future__ import annotations

import subprocess

import imageio_ffmpeg
import numpy as np
import pytest

from pipeline.frames.images import write_png, write_video


def _pngs(tmp_path, n, h=3, w=5):
    rng = np.random.default_rng(1)
    paths = []
    for i in range(n):
        p = tmp_path / f"beauty.{i + 1:04d}.png"
        write_png(p, rng.integers(0, 256, (h, w, 3), dtype=np.uint8))
        paths.append(p)
    return paths


def test_one_video_frame_per_png_and_even_size(tmp_path):
    video = tmp_path / "preview.mp4"
    assert write_video(_pngs(tmp_path, 7), video, 24.0) == 7
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(video))
    assert frames == 7
    # the first frame as raw RGB: 5x3 padded by one column and one row is 6 x 4 x 3 bytes
    raw = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-i", str(video), "-frames:v", "1",
                          "-f", "rawvideo", "-pix_fmt", "rgb24", "-"], capture_output=True, check=True).stdout
    assert len(raw) == 6 * 4 * 3
    assert write_video([], tmp_path / "none.mp4", 24.0) == 0 and not (tmp_path / "none.mp4").exists()


def test_a_broken_png_fails_naming_the_video_and_leaves_nothing(tmp_path):
    pngs = _pngs(tmp_path, 3)
    pngs[1].write_bytes(b"not a png at all")
    video = tmp_path / "preview.mp4"
    with pytest.raises(OSError, match="preview.mp4"):
        write_video(pngs, video, 24.0)
    assert not video.exists() and not list(tmp_path.glob("*.partial"))
