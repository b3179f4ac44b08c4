"""``loom report``: the run report opened in a real headless Chromium (tests/report/browser.py).

A small guided render of ROOM (two segments, every step of §5.2 runs) writes report.html; the file
is copied alone to another folder (it must need nothing beside it) and loaded: no console error,
the tables and plots are in the DOM, and the screenshot has drawn pixels where they are."""
from __future__ import annotations

import io
import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from pipeline.cli import main
from pipeline.config import RenderConfig, SegmentConfig
from pipeline.frames.settings import RenderSettings
from pipeline.run.render import RenderRequest, render
from pipeline.scene.builtin import write_builtin
from pipeline.segments.records import read_records
from tests.report.browser import load

CHEAP = dict(pilot_photons=2000, n_frame_min=1000, n_frame_max=16000, d_thr=0.45, fmax_initial=6, fmax_step=4,
             fmax_cap=10)

# Where each part of the page is, in page coordinates, read in the page after its load
GEOMETRY = """(() => { const out = {};
  for (const sel of ['table.table1', 'table.table2', '#segment-plot', '#fig6-plot', '#frame-plot', '#windows-plot',
                     '#aqm-0', '#frame-60', '#preview', 'table.config']) {
    const e = document.querySelector(sel); if (!e) { out[sel] = null; continue; }
    const r = e.getBoundingClientRect();
    out[sel] = [r.left + scrollX, r.top + scrollY, r.width, r.height,
                e.tagName === 'IMG' ? e.naturalWidth : -1]; }
  return out; })()"""
VIDEO = """new Promise(done => { const v = document.getElementById('preview');
  if (v.readyState >= 2) return done([v.readyState, v.duration]);
  v.addEventListener('loadeddata', () => done([v.readyState, v.duration]));
  v.addEventListener('error', () => done([-1, String(v.error && v.error.message)]));
  setTimeout(() => done([v.readyState, 'timeout']), 20000); })"""


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    scene = write_builtin("room", tmp / "room.glb")
    out = tmp / "out"
    request = RenderRequest(scene_path=scene, frames="60-80", out_dir=out,
                            settings=RenderSettings(width=96, height=72, spp=1),
                            config=RenderConfig(segments=SegmentConfig(**CHEAP)))
    first = render(request, scheduler="synchronous")
    again = render(request, scheduler="synchronous")  # everything is done: the rerun says what it skipped
    return out, first, again


def test_render_writes_a_self_contained_report(rendered):
    out = rendered[0]
    page = (out / "report.html").read_text()
    records = read_records(out)
    assert len(records) >= 2 and all(r.windows_at_k for r in records)
    for r in records:  # Fig. 5 counts every element the segment's photons hit, back and forward
        w = r.windows_at_k
        assert sum(w["back"]) == sum(w["fwd"]) == w["elements"] > 0 and len(w["back"]) == r.fmax // 2 + 1
    import re
    sources = re.findall(r'(?:src|poster|href)="([^"]*)"', page)
    assert sources and all(s.startswith("data:") for s in sources)  # nothing read from beside the file
    assert "<script" not in page


def test_report_opens_in_chromium_and_shows_tables_and_plots(rendered, tmp_path):
    out = rendered[0]
    result = CliRunner().invoke(main, ["report", str(out)])
    assert result.exit_code == 0 and "report.html" in result.output
    alone = tmp_path / "elsewhere" / "report.html"
    alone.parent.mkdir()
    shutil.copy(out / "report.html", alone)
    records = read_records(out)
    page = load(alone.as_uri(), {
        "geometry": GEOMETRY, "video": VIDEO,
        "table1_rows": "document.querySelectorAll('table.table1 tr').length",
        "table1_text": "document.querySelector('table.table1').innerText",
        "table2_text": "document.querySelector('table.table2').innerText",
        "skipped": "document.getElementById('skipped').innerText",
        "settings": "document.getElementById('settings').innerText",
        "thumbs": "document.querySelectorAll('img.thumb').length",
        "broken": "[...document.images].filter(i => !i.complete || i.naturalWidth === 0).length"})
    assert page["errors"] == []
    v = page["values"]
    assert v["table1_rows"] == len(records) + 1 and v["broken"] == 0 and v["thumbs"] >= 10
    for r in records:
        assert f"{r.n_frame:,}" in v["table1_text"] and f"{r.start}-{r.end}" in v["table1_text"]
        assert f"{r.d_aqm:.2f}" in v["table1_text"]
    assert "photon tracing" in v["table2_text"] and "ray tracing" in v["table2_text"]
    assert "segments already done: " + str(len(records)) in v["skipped"]
    assert "d_thr" in v["settings"] and "0.45" in v["settings"]
    state, duration = v["video"]
    assert state >= 2 and duration == pytest.approx(21 / 30, abs=0.05)  # 21 frames at 30 fps, decoded

    shot = np.asarray(Image.open(io.BytesIO(page["png"])).convert("RGB")).astype(np.int16)
    background = shot[5:40, -40:-5].reshape(-1, 3)  # the page's white margin
    assert np.all(background == 255)
    for sel, box in v["geometry"].items():
        assert box is not None, sel
        x, y, w, h, natural = (round(c) for c in box)
        assert w > 50 and h > 20 and natural != 0, sel
        if y + h > shot.shape[0]:
            continue  # below what the screenshot holds
        region = shot[y:y + h, x:x + w]
        drawn = np.any(np.abs(region - 255) > 30, axis=-1).mean()
        assert drawn > 0.02 and region.std() > 10, (sel, drawn, region.std())


def test_report_of_a_folder_without_a_render_is_one_line(tmp_path):
    result = CliRunner().invoke(main, ["report", str(tmp_path)])
    assert result.exit_code == 2 and "report.json" in result.output and "\n" == result.output[-1]
    assert not (tmp_path / "report.html").exists()


def test_rerun_reports_what_it_skipped(rendered):
    out, first, again = rendered
    s1, s2 = first["skipped_work"], again["skipped_work"]
    assert s1["segments_done"] == [] and s1["frames_skipping"].get("frame", 0) == 0
    assert [s["index"] for s in s2["segments_done"]] == [r.index for r in read_records(out)]
    assert s2["frames_skipping"]["frame"] == 21 and again["rendered"] == []
    # ROOM: moving geometry (a photon set a frame), a mirror sphere, no emissive triangles
    assert s1["photon_sets"] == 21 and s1["frames_skipping"].get("photons", 0) == 0
    assert s1["frames_skipping"]["area-light sampling"] == 21
    no_reflection = {int(f) for f, items in s1["per_frame"].items() if any(i["what"] == "reflection rays"
                                                                            for i in items)}
    assert no_reflection == {int(f) for f, r in first["rays_per_frame"].items() if r["reflection"] == 0}
    assert set(first["frame_times_s"]) == {str(f) for f in range(60, 81)}
    assert all(t["render_s"] > 0 for t in first["frame_times_s"].values())
    saved = json.loads((out / "report.json").read_text())
    assert saved["skipped_work"] == s2


def _record(index, start, end, *, n_frame=40_000, fmax=30, guided=False, d_aqm=None):
    from pipeline.segments.records import SegmentRecord
    return SegmentRecord(index=index, start=start, end=end, k=(start + end) // 2, fmax=fmax, n_frame=n_frame,
                         temporal="adaptive", guided=guided, decision_hash="x",
                         n_frame_steps=[] if d_aqm is None else [{"n_frame": n_frame, "d_aqm": d_aqm}])


def test_segment_plot_only_where_segments_differ_or_were_decided():
    """Fixed settings give one sentence with the two numbers instead of a plot of flat lines; a
    guided segment or segments with different settings get the plot."""
    from pipeline.report.page import _segment_picture
    fixed = _segment_picture([_record(0, 1, 40), _record(1, 41, 80)], {"d_thr": 0.03})
    assert 'id="segment-settings"' in fixed and "N_frame 40,000" in fixed and "F_max 30" in fixed
    assert "<img" not in fixed
    mixed = _segment_picture([_record(0, 1, 40), _record(1, 41, 80, n_frame=80_000)], {"d_thr": 0.03})
    guided = _segment_picture([_record(0, 1, 40, guided=True, d_aqm=2.5)], {"d_thr": 0.03})
    for html in (mixed, guided):
        assert 'id="segment-plot"' in html and "data:image/png;base64," in html


def test_a_capped_segment_gets_the_note_of_what_to_try(tmp_path):
    from dataclasses import replace

    from pipeline.report.page import _segments
    from pipeline.segments.records import CAPPED_NOTE

    config = {"d_thr": 0.03}
    done = _record(0, 1, 40, guided=True, d_aqm=2.5)
    capped = replace(_record(1, 41, 80, guided=True, d_aqm=4.0, n_frame=1_280_000), capped=True)
    assert 'id="capped"' not in _segments(tmp_path, [done], config)
    html = _segments(tmp_path, [done, capped], config)
    assert "4.00 (cap)" in html and 'id="capped"' in html and "loom bench elements" in CAPPED_NOTE
