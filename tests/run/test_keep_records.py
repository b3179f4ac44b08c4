"""The photon store keeps what a render reads: per-batch counts and sums by default, hit records
only with ``--keep-records`` (pipeline/store, pipeline/collection/batch_sums.py).

On ATRIUM's element mesh (about 23,600 elements, where a batch of 6,000 photons hits a fraction of
them and the sums are stored sparse) a render without records writes none and gives frames and
segment records bit-identical to one with them; its last lines say the store's size and bytes a
photon; a store of the previous format is refused in one line that says what to do, with nothing
written. The guided coordinator on ROOM is compared with and without records in
tests/coordinator/test_coordinator.py.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from pipeline.frames.images import frame_paths
from pipeline.segments.records import read_records
from pipeline.store import FORMAT_VERSION, PhotonStore, disk_usage

FRAMES = "150-153"


def _loom(*args):
    return subprocess.run([sys.executable, "-m", "pipeline", *map(str, args)], capture_output=True, text=True)


def _render(scene, out, *extra):
    result = _loom("render", scene, "--frames", FRAMES, "--out", out, "--resolution", "48x36", "--spp", "1",
                   "--photons", "6000", "--fmax", "4", "--scheduler", "synchronous", *extra)
    assert result.returncode == 0, result.stderr
    return result.stdout


def _frames(out):
    first, last = map(int, FRAMES.split("-"))
    return {f: tuple(p.read_bytes() for p in frame_paths(out, f)) for f in range(first, last + 1)}


@pytest.fixture(scope="module")
def atrium(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("keep")
    scene = tmp / "atrium.glb"
    assert _loom("scene", "atrium", "-o", scene).returncode == 0
    said = {name: _render(scene, tmp / name, *flags) for name, flags in
            (("sums", ()), ("records", ("--keep-records",)))}
    return tmp, scene, said


def test_a_render_without_records_writes_none_and_the_same_bits(atrium):
    tmp, _, _ = atrium
    sums, records = tmp / "sums", tmp / "records"
    assert _frames(sums) == _frames(records)
    assert [r.without_times() for r in read_records(sums)] == [r.without_times() for r in read_records(records)]
    plain, kept = PhotonStore.open(sums / "photons.zarr"), PhotonStore.open(records / "photons.zarr")
    assert not plain.keep_records and kept.keep_records
    assert not (sums / "photons.zarr" / "frames").exists()
    size_plain, size_kept = disk_usage(str(sums / "photons.zarr")), disk_usage(str(records / "photons.zarr"))
    assert size_plain["records"] == 0 and size_kept["records"] > 0
    assert abs(size_plain["photons"] - size_kept["photons"]) < 16  # the same counts and sums (and a flag)
    # The sums of a small batch on a fine mesh are sparse: fewer bytes than dense float32 sums would take
    summaries = list((sums / "photons.zarr" / "batch").iterdir())  # one object a batch: counts and sums
    assert len(summaries) == 4
    assert sum(p.stat().st_size for p in summaries) < len(summaries) * plain.n_elements * 24 * 4 / 3


def test_the_last_lines_and_the_report_give_the_store_size(atrium):
    tmp, _, said = atrium
    line = next(ln for ln in said["sums"].splitlines() if ln.startswith("photon store"))
    assert "bytes a photon" in line and "(no hit records)" in line
    assert "hit records" in next(ln for ln in said["records"].splitlines() if ln.startswith("photon store"))
    report = json.loads((tmp / "sums" / "report.json").read_text())
    size = report["store_size"]
    assert size["photons"] == 4 * 6000 and not size["keep_records"]
    assert size["bytes_per_photon"] == pytest.approx(
        (size["bytes"]["photons"] + size["bytes"]["records"]) / size["photons"])
    assert "bytes a photon" in (tmp / "sums" / "report.html").read_text()
    # Table 2's I/O row says what moved: the segment records count the bytes the tasks read and wrote
    moved = read_records(tmp / "sums")[0].io_bytes
    assert moved["shoot_write_bytes"] > 0 and moved["reconstruct_read_bytes"] > 0


def test_keep_records_is_not_changed_on_a_rerun(atrium):
    tmp, scene, _ = atrium
    result = _loom("render", scene, "--frames", FRAMES, "--out", tmp / "sums", "--resolution", "48x36", "--spp",
                   "1", "--photons", "6000", "--fmax", "4", "--scheduler", "synchronous", "--keep-records")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "holds no hit records" in result.stderr and "photons.zarr" in result.stderr


def test_a_store_of_the_previous_format_is_refused_in_one_line(atrium):
    tmp, scene, _ = atrium
    out = tmp / "old"
    shutil.copytree(tmp / "sums", out)
    meta = out / "photons.zarr" / "zarr.json"
    data = json.loads(meta.read_text())
    data["attributes"]["format_version"] = FORMAT_VERSION - 1
    del data["attributes"]["keep_records"]  # the previous format had none
    meta.write_text(json.dumps(data))
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    result = _loom("render", scene, "--frames", FRAMES, "--out", out, "--resolution", "48x36", "--spp", "1",
                   "--photons", "6000", "--fmax", "4", "--scheduler", "synchronous")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert f"format version {FORMAT_VERSION - 1}" in lines[0] and "delete it" in lines[0]
    assert str(out / "photons.zarr") in lines[0]
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == before  # nothing written


def test_the_viewing_conditions_are_said_with_their_pixels_per_degree(atrium):
    """loom render prints the display the AQM assumes and the pixels per degree it gives; the report
    shows the same line; --display names another of ColorVideoVDP's displays."""
    tmp, _, said = atrium
    line = next(ln for ln in said["sums"].splitlines() if ln.startswith("viewing "))
    assert "standard_fhd" in line and "full screen" in line and "frame 48x36 at" in line and "px/deg" in line
    report = json.loads((tmp / "sums" / "report.json").read_text())
    assert report["viewing"] == line
    from pipeline.frames.perceived import viewing_for
    from pipeline.frames.tonemap import ToneMapping
    fhd, uhd = (viewing_for(ToneMapping(display=d)) for d in ("standard_fhd", "standard_4k"))
    # full screen, a 48x36 frame is shown 30x magnified on either: 4k's larger screen at a
    # longer distance gives fewer frame pixels per degree than the 24-inch fhd
    assert uhd.frame_ppd((36, 48)) != fhd.frame_ppd((36, 48))
    assert f"{fhd.frame_ppd((36, 48)):.1f} px/deg" in line
