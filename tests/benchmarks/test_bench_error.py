"""``loom bench error``: its measures on synthetic inputs with known answers, and the whole machinery
(real renders on a LocalCluster, real references) on a tiny CORNELL run."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.benchmarks import error_measures as em
from pipeline.benchmarks.error import REFERENCE_SOURCES, Plan, reference_key, run
from pipeline.errors import LoomError
from pipeline.scene import read_scene


def _maps(rng, frames=10, vertices=50):
    areas = rng.uniform(0.5, 2.0, vertices)
    base = rng.uniform(0.2, 1.0, (vertices, 3))
    return areas, base


def test_relative_l2_and_image_errors_known_values(rng):
    areas, ref = _maps(rng)
    assert em.relative_l2(1.1 * ref, ref, areas) == pytest.approx(0.1)
    img = np.full((4, 5, 3), 0.5)
    rmse, mean_rel = em.image_errors(img + 0.1, img)
    assert rmse == pytest.approx(0.1) and mean_rel == pytest.approx(0.2)


def test_flicker_of_an_alternating_error_and_of_a_steady_bias(rng):
    areas, ref = _maps(rng)
    refs = np.stack([ref] * 6)
    sign = np.array([1, -1, 1, -1, 1, -1], float)[:, None, None]
    # e(t) = +-0.05 R: |e(t) - e(t-1)| = 0.1 ||R|| every interval
    assert np.allclose(em.flicker(refs * (1 + 0.05 * sign), refs, areas), 0.1)
    # a bias that stays put does not flicker, however large
    assert np.allclose(em.flicker(refs * 1.3, refs, areas), 0.0)
    imgs = np.full((6, 3, 4, 3), 0.4)
    assert np.allclose(em.image_flicker(imgs * (1 + 0.05 * sign[:, :, :, None]), imgs), 0.1)


def _step(rng, n=12, event=5):
    areas, r0 = _maps(rng)
    r1 = r0 * rng.uniform(1.5, 3.0, r0.shape)  # a light jumps: every vertex changes
    refs = np.stack([r0 if t < event else r1 for t in range(n)])
    return areas, refs


def test_lag_of_per_frame_fixed_windows_and_a_frozen_method(rng):
    areas, refs = _step(rng)
    event = 5
    # Per-frame rendering shows the change at once
    assert em.lag(em.step_response(refs, refs, areas, event)) == (0, True)
    # Fixed +-3 windows: at frame event + k the window holds 4 + k of its 7 frames after the change:
    # responses 4/7, 5/7, 6/7, 7/7, so 90 % is reached 3 frames late
    padded = np.concatenate([refs[:1].repeat(3, 0), refs, refs[-1:].repeat(3, 0)])
    fixed = np.stack([padded[t:t + 7].mean(axis=0) for t in range(len(refs))])
    response = em.step_response(fixed, refs, areas, event)
    assert np.allclose(response[:4], [4 / 7, 5 / 7, 6 / 7, 1.0])
    assert em.lag(response) == (3, True)
    # A method that never shows the change: censored at the frames it had
    frozen = np.stack([refs[0]] * len(refs))
    assert em.lag(em.step_response(frozen, refs, areas, event)) == (len(refs) - event, False)
    # Noise orthogonal to the change does not move the response
    d = (refs[event] - refs[event - 1]).ravel()
    noise = rng.standard_normal(d.shape)
    w = np.repeat(areas, 3)
    noise -= d * np.sum(w * noise * d) / np.sum(w * d * d)
    noisy = refs + noise.reshape(refs.shape[1:])
    assert np.allclose(em.step_response(noisy, refs, areas, event), 1.0)
    assert em.largest_change(refs, areas)[0] == event


def test_equal_time_and_equal_error_on_a_known_power_law():
    photons = np.array([1e5, 2e5, 4e5])
    times = 1.0 + 1e-5 * photons  # 1 s fixed cost, 10 s per million photons
    errors = 0.1 * (photons / 1e5) ** -0.5
    assert em.cost_model(photons, times) == pytest.approx((1.0, 1e-5))
    assert em.equal_time(photons, times, errors, 3.0) == (pytest.approx(0.1 / np.sqrt(2)), False)
    e, extrapolated = em.equal_time(photons, times, errors, 9.0)  # 800,000 photons: beyond the runs
    assert e == pytest.approx(0.1 / np.sqrt(8)) and extrapolated
    assert em.equal_time(photons, times, errors, 0.5) == (None, True)  # less than the fixed cost
    t, extrapolated = em.equal_error(photons, times, errors, 0.05)
    assert t == pytest.approx(5.0) and not extrapolated
    # Jitter hiding the per-photon cost (times falling with photons): the given slope, mean remainder
    jittered = np.array([5.0, 4.9, 4.8])
    assert em.cost_model(photons, jittered, 1e-6) == pytest.approx((np.mean(jittered - 1e-6 * photons), 1e-6))


def test_brightest_region_holds_its_share_of_the_area(rng):
    areas, ref = _maps(rng, vertices=400)
    region = em.brightest_region(ref, areas, share=0.1)
    y = ref @ em.LUMA
    assert areas[region].sum() >= 0.1 * areas.sum()
    assert y[region].min() >= y[~region].max()
    assert em.region_energy(2 * ref, areas, region) == pytest.approx(2 * em.region_energy(ref, areas, region))


def test_bench_error_runs_end_to_end_on_a_tiny_cornell(tmp_path):
    plan = Plan((1, 4), (1_000, 2_000), 2, (0.5,), width=48, height=36, spp=1)
    lines = []
    result = run("cornell", plan, tmp_path / "out", workers=1, echo=lines.append)
    for name in ("error.json", "error.png", "error.svg"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    saved = json.loads((tmp_path / "out" / "error.json").read_text())
    methods = [r["method"] for r in saved["runs"]]
    assert methods == ["per-frame"] * 2 + ["fixed"] * 2 + ["adaptive"] * 2 + ["guided"]
    per_frame = {r["n_photons"]: r for r in result["runs"] if r["method"] == "per-frame"}
    assert per_frame[1_000]["photons"] == 4 * 1_000 and per_frame[2_000]["photons"] == 4 * 2_000
    assert saved["reference"]["photons"] == 50 * 2_000
    floor = saved["reference"]["floor"]
    for r in saved["runs"]:
        assert r["wall_s"] > 0 and r["cpu_s"] > 0
        # Every method is farther from the reference than the reference's second seed
        assert r["measures"]["rel_l2"] > floor["rel_l2"]
    assert len(saved["comparison"]["wall_s"]["rows"]) == len(saved["comparison"]["cpu_s"]["rows"]) == 5
    # FLIP beside d_AQM, on the same frames: a mean in [0, 1], larger the noisier the run (half the
    # photons of per-frame rendering; the reference's second seed least of all)
    for m in [floor] + [r["measures"] for r in saved["runs"]]:
        assert math.isfinite(m["flip"]) and 0.0 <= m["flip"] <= 1.0
    for r in saved["runs"]:
        assert r["measures"]["per_frame"]["flip"].keys() == r["measures"]["per_frame"]["d_aqm"].keys()
    assert floor["flip"] < per_frame[2_000]["measures"]["flip"] < per_frame[1_000]["measures"]["flip"]
    for row in saved["comparison"]["cpu_s"]["rows"]:
        flip = row["flip"]
        assert flip["ratio"] is None or flip["ratio"] == pytest.approx(flip["run"] / flip["per_frame_at_equal_time"])
    assert any("| FLIP |" in line for line in lines)
    assert any("FLIP, per-frame's at equal time" in line for line in lines)
    # The flicker of each run's photon noise alone (its even/odd halves in its own windows): less with
    # more photons, and less in windows that slide over frames than in a frame's own photons
    noise = {(r["method"], r["n_photons"]): r["measures"]["flicker_noise"] for r in saved["runs"]}
    assert all(math.isfinite(v) and v > 0 for v in noise.values())
    assert noise[("per-frame", 1_000)] > noise[("per-frame", 2_000)]
    assert noise[("fixed", 1_000)] < noise[("per-frame", 1_000)]
    assert floor["flicker_noise"] is None and any("| of it photon noise |" in line for line in lines)
    # The guided run's bound with hindsight of the light, at its photons; the fixed-budget runs have none
    for r in saved["runs"]:
        bound = r["measures"]["flicker_hindsight"]
        assert (bound is None) == (r["method"] != "guided")
        assert bound is None or (math.isfinite(bound) and bound > 0)
    assert any("windows chosen with hindsight of the light would flicker" in line for line in lines)
    assert saved["event"]["frame"] == plan.event == 3
    assert any(line.startswith("| per-frame 1,000 |") for line in lines)
    # What the machine charged before and after the runs is printed and kept beside the figures
    assert set(saved["machine"]) == {"before", "after"} and all(
        v > 0 for costs in saved["machine"].values() for v in costs.values())
    assert any(line.startswith("machine before: a new 1.5 MB file") for line in lines)
    # No temporary folder is left beside the results; the references are kept for a rerun
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["error.json", "error.png", "error.svg",
                                                                   "references"]
    (cache,) = (tmp_path / "out" / "references").iterdir()
    assert cache.suffix == ".npz" and saved["reference"]["file"] == str(cache)

    # A rerun with other budgets of the same reference size reuses it, and measures the same floor
    lines.clear()
    again = run("cornell", Plan((1, 4), (2_000,), 2, (0.5,), width=48, height=36, spp=1), tmp_path / "out",
                workers=1, echo=lines.append)
    assert any(line.startswith(f"references: reused {cache}") for line in lines)
    assert again["reference"]["floor"] == saved["reference"]["floor"]
    assert [r["method"] for r in again["runs"]] == ["per-frame", "fixed", "adaptive", "guided"]


def test_reference_key_names_everything_the_reference_reads():
    base = dict(scene_hash="abc", element_size=0.1, frames=(1, 4), n_photons=1000, seeds=(101, 202), max_depth=256)
    key = reference_key(**base)
    assert reference_key(**base) == key
    for change in (dict(scene_hash="abd"), dict(element_size=0.2), dict(frames=(1, 5)), dict(n_photons=1001),
                   dict(seeds=(101, 203)), dict(max_depth=8)):
        assert reference_key(**{**base, **change}) != key


def test_reference_key_reads_the_tracer_it_names():
    """Every source the key hashes exists (a moved tracer must not drop out of the key unnoticed)
    and the tracer is among them."""
    root = Path(__file__).resolve().parents[2]
    assert all((root / s).exists() for s in REFERENCE_SOURCES)
    assert any((root / s / "tracing.py").exists() for s in REFERENCE_SOURCES)


def test_bench_error_refuses_a_reference_under_50x(tmp_path):
    with pytest.raises(LoomError, match="at least 50"):
        run("cornell", Plan((1, 4), (1_000,), 2, (0.5,), reference_factor=10), tmp_path / "out")


def test_bench_error_is_a_bench_command():
    from pipeline.cli import main

    out = CliRunner().invoke(main, ["bench", "error", "--help"])
    assert out.exit_code == 0 and "--quick" in out.output


def test_a_reference_draws_the_same_random_numbers_in_every_frame(tmp_path):
    """Common random numbers: where two frames' scenes are the same (the STATIC scene: only its camera
    moves), one reference's maps are the same bits, so its noise adds nothing to the error's flicker;
    another stream gives another estimate of the same light (a noise the floor measures)."""
    from pipeline.benchmarks.error import reference_map
    from pipeline.scene import ElementMesh
    from pipeline.scene.builtin import write_builtin

    path = write_builtin("static", tmp_path / "static.glb")
    scene = read_scene(path)
    elements = ElementMesh.build(scene)
    common = dict(scene_path=str(path), scene_hash=scene.scene_hash, element_size=elements.element_size,
                  n_photons=3_000, seed=101, max_depth=256)
    a = reference_map(frame=1, stream=1, **common)
    b = reference_map(frame=2, stream=1, **common)
    other = reference_map(frame=2, stream=2, **common)
    assert a.sum() > 0 and np.array_equal(a, b)
    assert not np.array_equal(a, other)
    assert other.sum() == pytest.approx(a.sum(), rel=0.1)


def test_the_reference_basis_says_what_the_uncapped_guided_run_reached():
    """The guided runs are uncapped (as loom render runs them), the reference stays 50x the largest budget,
    and the output says how many times the guided run's largest N_frame it holds and what 50x the cap costs."""
    from pipeline.benchmarks.error import reference_basis
    from pipeline.config import SegmentConfig

    plan = Plan((1, 4), (1_000, 2_000), 2, (0.5,))
    runs = [{"method": "per-frame", "segments": []},
            {"method": "guided", "segments": [{"n_frame": 4_000}, {"n_frame": 16_000}]}]
    basis = reference_basis(plan, runs, SegmentConfig(), ref_photons=2 * 100_000 * 4, ref_s=8.0)
    assert basis["sized_by"] == "largest budget" and basis["guided_n_frame"] == 16_000
    assert basis["factor_of_guided"] == 100_000 / 16_000
    assert basis["cap_reference_photons"] == 50 * 1_280_000 and basis["cap_reference_s"] == 8.0 * 640
    assert "reached N_frame 16,000" in basis["statement"] and "under 50x" in basis["statement"]
    assert reference_basis(plan, runs[:1], SegmentConfig(), 800_000, 8.0)["statement"] == ""


def test_centre_weights_are_a_mean_and_a_parabola_through_the_frames():
    np.testing.assert_allclose(em.centre_weights(3, 0), np.full(7, 1 / 7))
    np.testing.assert_allclose(em.centre_weights(3, 1), np.full(7, 1 / 7))  # a line's centre is the mean
    x = np.arange(-4, 5.0)
    w = em.centre_weights(4, 2)
    assert w.sum() == pytest.approx(1.0) and w @ x == pytest.approx(0.0, abs=1e-12)
    assert w @ (3.0 + 2.0 * x - 0.5 * x * x) == pytest.approx(3.0)  # a parabola's value at the frame, exactly
    np.testing.assert_allclose(em.centre_weights(1, 2), [0, 1, 0], atol=1e-12)  # three frames hold it exactly
    assert np.array_equal(em.centre_weights(0, 2), [1.0])


def test_symmetric_windows_stop_at_the_ends_and_at_a_cut():
    refs = np.zeros((9, 1, 3))
    refs[5:] = 1.0  # a step between frames 4 and 5
    across = em.symmetric_windows(refs, 2, 0)
    assert across[4, 0, 0] == pytest.approx(2 / 5)  # frames 2-6 mix both sides
    kept = em.symmetric_windows(refs, 2, 0, cut=5)
    np.testing.assert_array_equal(kept, refs)  # every window stays on its own side: the step is kept whole
    assert em.symmetric_windows(refs, 8, 0)[0, 0, 0] == 0.0  # frame 0 has no frames before it: itself


def test_hindsight_flicker_of_steady_light_is_the_longest_mean_s_noise():
    """Steady light with photon noise of variance s2 a frame: no window has bias, the longest mean
    (2h + 1 = 31 frames) the least noise flicker, 2 s2 / 31^2 relative to ||R||^2 = 3 V."""
    n, v, s2 = 40, 50, 0.04
    refs = np.ones((n, v, 3))
    bound = em.hindsight_flicker(refs, np.full(v, s2), np.ones(v))
    assert bound == pytest.approx(np.sqrt(2 * s2 / 31 ** 2 / 3))


def test_hindsight_flicker_of_noise_free_light_is_nil_and_a_cut_keeps_a_step(rng):
    """Without photon noise each frame alone is exact, whatever the light does; steady light that
    steps once flickers at the steady bound where no window crosses the step, and more where they may."""
    n, v = 40, 30
    moving = rng.uniform(0.5, 2.0, (n, v, 3))
    assert em.hindsight_flicker(moving, np.zeros(v), np.ones(v)) == 0.0
    step = np.ones((n, v, 3))
    step[20:] = 3.0
    noise = np.full(v, 0.04)
    steady = em.hindsight_flicker(np.ones((n, v, 3)), noise, np.ones(v), 20)
    kept = em.hindsight_flicker(step, noise, np.ones(v), 20)
    crossed = em.hindsight_flicker(step, noise, np.ones(v))
    assert kept < crossed
    # the same windows as steady light, each pair's flicker relative to its own frame's light (9x after the step)
    relative = np.where(np.arange(1, n) < 20, 1.0, 1 / 9)[np.arange(n - 1) != 19]
    assert kept == pytest.approx(steady * np.sqrt(np.mean(relative)), rel=1e-9)
