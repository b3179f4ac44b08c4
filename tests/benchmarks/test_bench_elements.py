"""``loom bench elements``: the decision rule and the difference picture on inputs with known answers, and a
tiny real run that is repeatable to the bit and writes its table and picture."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.benchmarks.elements import coarsest_invisible_scale, difference_picture, run
from pipeline.errors import LoomError
from pipeline.frames.images import read_png


def _rows(d: dict[float, list[float]]) -> list[dict]:
    return [dict(frame=f, scale=s, d_aqm=v) for s, values in d.items() for f, v in enumerate(values)]


def test_coarsest_invisible_scale_takes_the_worst_frame_and_every_finer_scale():
    rows = _rows({0.75: [0.5, 1.0], 1.0: [2.0, 2.9], 1.5: [2.5, 4.0], 2.0: [1.0, 1.0]})
    assert coarsest_invisible_scale(rows, 3.0) == 1.0  # 1.5 fails on frame 1
    assert coarsest_invisible_scale(rows, 4.0) == 2.0
    assert coarsest_invisible_scale(rows, 0.9) is None  # the finest compared already fails
    # a coarser scale under the threshold does not pass over a finer one above it
    assert coarsest_invisible_scale(_rows({1.0: [5.0], 2.0: [1.0]}), 3.0) is None


def test_difference_picture_is_red_where_brighter_blue_where_darker_and_saturates():
    ref = np.full((1, 4, 3), 1.0)
    test = ref * np.array([1.0, 1.05, 0.8, 1.2])[None, :, None]
    pic = difference_picture(test, ref, full_scale=0.1)
    assert pic[0, 0].tolist() == [0, 0, 0]
    assert pic[0, 1].tolist() == [128, 0, 0]  # +5 % of the mean: half red
    assert pic[0, 2].tolist() == [0, 0, 255] and pic[0, 3].tolist() == [255, 0, 0]


@pytest.mark.timeout(600)
def test_tiny_run_is_repeatable_and_writes_its_table_and_picture(tmp_path):
    kw = dict(frames=(1,), scales=(1.0, 2.0), photons=20_000, width=32, height=24, spp=1, scheduler="synchronous",
              echo=lambda s: None)
    first = run("cornell", out_dir=tmp_path / "a", **kw)
    again = run("cornell", out_dir=tmp_path / "b", **kw)
    (row,) = first["rows"]
    assert row["scale"] == 2.0 and row["elements"] < first["finest"]["elements"]
    assert row["rel_rms"] > 0.0 and first["floor"][0]["rel_rms"] > 0.0  # other elements, another seed: not the bits
    for key in ("d_aqm", "flip", "rel_rms"):
        assert again["rows"][0][key] == row[key] and again["floor"][0][key] == first["floor"][0][key]
    written = json.loads((tmp_path / "a" / "elements.json").read_text())
    assert written["rows"] == first["rows"]
    # 20,000 photons converge nothing: the floor is over d_thr and no scale is chosen from noise
    assert not written["converged"] and written["coarsest_invisible_scale"] is None
    assert max(f["d_aqm"] for f in written["floor"]) > written["d_thr_percent"]
    assert read_png(tmp_path / "a" / "elements.png").shape[:2] == (24, 64)  # the frame, then the one difference
    # the scales multiply a given element size instead of the scene's
    other = run("cornell", out_dir=tmp_path / "c", element_size=0.5 * first["finest"]["element_size"], **kw)
    assert other["finest"]["element_size"] == 0.5 * first["finest"]["element_size"]
    assert other["rows"][0]["elements"] > row["elements"]


def test_a_single_scale_or_a_frame_outside_the_scene_is_refused_and_writes_nothing(tmp_path):
    with pytest.raises(LoomError, match="--scales"):
        run("cornell", frames=(1,), scales=(1.0,), out_dir=tmp_path, echo=lambda s: None)
    with pytest.raises(LoomError, match="--element-size"):
        run("cornell", frames=(1,), scales=(1.0, 2.0), element_size=0.0, scheduler="synchronous",
            out_dir=tmp_path / "out", echo=lambda s: None)
    with pytest.raises(LoomError, match="--frames"):
        run("cornell", frames=(9999,), scales=(1.0, 2.0), scheduler="synchronous", out_dir=tmp_path / "out",
            echo=lambda s: None)
    assert not (tmp_path / "out").exists()
