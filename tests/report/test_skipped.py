"""What a render skips (pipeline/report/skipped.py): the pure account, and camera-only motion end to end."""
from __future__ import annotations

import json

from click.testing import CliRunner

from pipeline.cli import main
from pipeline.report.skipped import skipped_work, summary_lines
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore


def test_each_kind_of_skip_names_its_reason():
    rays = {1: {"reflection": 0, "area": 5}, 2: {"reflection": 9, "area": 0}}
    s = skipped_work([1, 2, 3], sources={1: 1, 2: 1, 3: 3}, has_specular=True, has_area_lights=True, rays=rays,
                     segments_done=[{"index": 0, "frames": [3, 3]}])
    why = {f: {i["what"]: i["why"] for i in items} for f, items in s["per_frame"].items()}
    assert why["1"] == {"reflection rays": "no specular surface in view"}
    assert why["2"]["photons"] == "nothing but the camera moves since frame 1: shares its photons"
    assert why["2"]["area-light sampling"] == "no diffuse surface in view takes area or sky light"
    assert why["3"] == {"frame": "already done: its files carry the current frame hash"}
    assert s["photon_sets"] == 2 and s["frames_skipping"] == {"reflection rays": 1, "photons": 1,
                                                             "area-light sampling": 1, "frame": 1}
    plain = skipped_work([1, 2], sources={1: 1, 2: 2}, has_specular=False, has_area_lights=False, rays=None,
                         segments_done=[])
    assert all({i["what"] for i in items} == {"reflection rays", "area-light sampling"}
               for items in plain["per_frame"].values())
    assert any("segments already done: 1 (0: frames 3-3)" == line for line in summary_lines(s))
    assert "segments without indirect light (N_frame the smallest rung): 0" in summary_lines(s)
    unlit = skipped_work([1, 2], sources={1: 1, 2: 2}, has_specular=False, has_area_lights=False, rays=None,
                         segments_done=[], segments_unlit=[{"index": 0, "frames": [1, 2], "n_frame": 1250}])
    assert "segments without indirect light (N_frame the smallest rung): 1 (0: frames 1-2 at 1,250)" \
        in summary_lines(unlit)


def test_camera_only_motion_traces_one_photon_set_at_fixed_settings(tmp_path):
    scene = write_builtin("static", tmp_path / "static.glb")
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(scene), "--frames", "1-12", "--out", str(out), "--resolution",
                                       "40x30", "--spp", "1", "--photons", "3000", "--fmax", "4", "--scheduler",
                                       "synchronous"])
    assert result.exit_code == 0, result.output
    report = json.loads((out / "report.json").read_text())
    store = PhotonStore.open(out / "photons.zarr")
    assert [store.source_frame(f) for f in range(12)] == [0] * 12
    assert report["photon_batches_traced"] == 1 and store.photons_emitted(0) == 3000
    assert all(store.photons_emitted(f) == 3000 for f in range(12))  # shared, not traced again
    s = report["skipped_work"]
    assert s["photon_sets"] == 1 and s["frames_skipping"]["photons"] == 11
    assert "1" not in s["per_frame"] or all(i["what"] != "photons" for i in s["per_frame"]["1"])
    assert "skipped: photon sets traced: 1 for 12 frames (one set for the whole animation" in result.output
    assert (out / "report.html").is_file()


def test_a_sky_is_sampled_like_an_area_light_and_is_not_called_skipped(tmp_path):
    # the pure account: a sky without emissive triangles takes area rays
    s = skipped_work([1], sources={1: 1}, has_specular=False, has_area_lights=False, rays={1: {"area": 40}},
                     segments_done=[], has_sky=True)
    assert "area-light sampling" not in {i["what"] for i in s["per_frame"]["1"]}
    # end to end: a plane with no light of its own renders under the default sun and sky
    from pipeline.frames.settings import RenderSettings
    from pipeline.run.render import RenderRequest, render
    from pipeline.scene.builtin.gltf_builder import GltfBuilder
    from tests.frames.scenes import UP_FACES, camera, quad_y

    b = GltfBuilder()
    b.add_node("plane", b.add_mesh("plane", quad_y(2.0), UP_FACES, material=b.add_material("plane", (0.5,) * 3)))
    camera(b, (0.0, 3.0, 0.0), (0.0, 0.0, 0.0))
    b.set_scene_extras({"photonloom": {"element_size": 1.0}})
    scene = b.write(tmp_path / "unlit.glb")
    report = render(RenderRequest(scene_path=scene, frames="1", out_dir=tmp_path / "out",
                                  settings=RenderSettings(width=16, height=12, spp=1), n_photons=500),
                    scheduler="synchronous")
    assert report["rays"]["area"] > 0
    assert report["skipped_work"]["frames_skipping"].get("area-light sampling", 0) == 0
    assert "frames with no area-light sampling: 0 of 1" in summary_lines(report["skipped_work"])
