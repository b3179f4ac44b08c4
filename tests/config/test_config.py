"""The stage configs and their composition (pipeline/config.py): validation per stage, the flat
``--config`` form, and digests that key stores, task keys and EXR headers staying what they were."""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from pipeline.config import (
    CollectionConfig,
    FilterConfig,
    PhotonConfig,
    RenderConfig,
    SegmentConfig,
    load_config,
)
from pipeline.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
STAGE_CONFIGS = {"photons": PhotonConfig, "collection": CollectionConfig, "filter": FilterConfig,
          "segments": SegmentConfig}

# Digests of the defaults and of one changed config, as stores and frames written so far carry them:
# a new digest for the same settings would refuse every existing store and redo every frame.
DEFAULT_HASH = "3eb7abe9d91f856a"
DEFAULT_STAGE_HASHES = {"photons": "dc8448b0552542a6", "collection": "74f304dcae925cd5",
                        "filter": "57e4833c505322c6", "segments": "a1e814344303c399"}
CHANGED = {"d_thr": 0.02, "element_size": 0.3, "seed": 7}
CHANGED_HASH = "981eb47d698360eb"
CHANGED_STAGE_HASHES = {"photons": "113f75cd76b23228", "segments": "309235d933487e50"}


def test_the_digests_are_those_of_the_flat_config():
    config = RenderConfig()
    assert config.hash == DEFAULT_HASH
    assert {name: getattr(config, name).hash for name in STAGE_CONFIGS} == DEFAULT_STAGE_HASHES
    assert config.photons.photon_hash(0.1) == "87fa24b219af8029"
    assert config.photons.photon_hash(0.25) == "f003b5d02bf593c7"
    changed = RenderConfig.from_dict(CHANGED)
    assert changed.hash == CHANGED_HASH
    want = {**DEFAULT_STAGE_HASHES, **CHANGED_STAGE_HASHES}
    assert {name: getattr(changed, name).hash for name in STAGE_CONFIGS} == want
    assert changed.photons.photon_hash(0.3) == "f38142f466855572"


def test_each_stage_hash_covers_only_its_stage():
    base = RenderConfig()
    changed = {"segments": {"d_thr": 0.05, "p_thr": 0.5}, "collection": {"k_sigma": 3.0},
               "filter": {"filter_photons": 9.0}, "photons": {"photon_depth": 3}}
    for stage, changes in changed.items():
        for name, value in changes.items():
            other = RenderConfig.from_dict({**base.to_dict(), name: value})
            for s in STAGE_CONFIGS:
                assert (getattr(other, s).hash != getattr(base, s).hash) == (s == stage), (name, s)
    assert base.segments.replace(d_thr=0.05) != base.segments
    assert PhotonConfig(seed=4).photon_hash(0.4) == PhotonConfig().photon_hash(0.4)  # the seed is stored apart
    assert PhotonConfig(photon_depth=3).photon_hash(0.4) != PhotonConfig().photon_hash(0.4)


def test_the_flat_form_round_trips_in_the_fields_order():
    config = RenderConfig(photons=PhotonConfig(seed=3), segments=SegmentConfig(d_thr=0.1, fmax_cap=30))
    flat = config.to_dict()
    names = [f.name for stage in STAGE_CONFIGS.values() for f in dataclasses.fields(stage)]
    assert list(flat) == names and len(set(names)) == len(names)  # one flat name, one owner
    assert RenderConfig.from_dict(flat) == config
    assert RenderConfig.from_dict({}) == RenderConfig()
    assert RenderConfig.from_dict({"d_thr": 0.02}).segments.d_thr == 0.02


def test_unknown_names_are_refused_in_one_line():
    with pytest.raises(ConfigError, match=r"^config: unknown parameter\(s\) bogus, photons$"):
        RenderConfig.from_dict({"bogus": 1, "photons": {}, "d_thr": 0.02})


@pytest.mark.parametrize("stage, name, value", [
    (PhotonConfig, "element_size", 0.0), (PhotonConfig, "seed", -1), (PhotonConfig, "photon_depth", 1025),
    (PhotonConfig, "seed", 1.5),
    (CollectionConfig, "k_sigma", 0.0), (CollectionConfig, "smoothing_frames", 4),
    (CollectionConfig, "step_levels", 17), (CollectionConfig, "step_relative", 1.5),
    (FilterConfig, "spatial_filter", "yes"), (FilterConfig, "filter_angle", 181.0),
    (FilterConfig, "filter_z", float("nan")),
    (SegmentConfig, "d_thr", 2.0), (SegmentConfig, "end_photons", 0.999), (SegmentConfig, "aqm_size", True),
])
def test_each_stage_config_checks_its_fields(stage, name, value):
    with pytest.raises(ConfigError, match=rf"^{name}: invalid value") as err:
        stage(**{name: value})
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match=rf"^{name}: invalid value"):  # the flat form says the same
        RenderConfig.from_dict({name: value})


def test_bounds_and_the_cross_field_check():
    assert PhotonConfig(element_size=None).element_size is None  # optional: the scene's
    assert SegmentConfig(end_photons=1.0).end_photons == 1.0  # a closed lower bound
    assert SegmentConfig(fmax_initial=44).fmax_initial == 44
    with pytest.raises(ConfigError, match="^fmax_initial: fmax_initial 45 exceeds fmax_cap 44$"):
        SegmentConfig(fmax_initial=45)
    with pytest.raises(ConfigError, match="exceeds fmax_cap"):
        SegmentConfig().replace(fmax_cap=10)


def test_every_field_names_its_paper_symbol():
    for stage in STAGE_CONFIGS.values():
        for f in dataclasses.fields(stage):
            assert f.metadata["symbol"].strip(), f"{stage.__name__}.{f.name}"


def test_every_config_field_is_read_outside_config():
    text = "\n".join(p.read_text() for d in ("pipeline", "workers", "kernels") for p in (ROOT / d).rglob("*.py")
                     if p.name != "config.py")
    for stage in STAGE_CONFIGS.values():
        for f in dataclasses.fields(stage):
            assert re.search(rf"\.{f.name}\b", text), f"{stage.__name__}.{f.name} is read by nothing"


def test_load_config_names_the_file_and_the_field(tmp_path):
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text('{"d_thr": 0.02, "filter_rings": 2}')
    bad.write_text('{"filter_rings": 0}')
    assert RenderConfig.from_dict(load_config(good)).filter.filter_rings == 2
    with pytest.raises(ConfigError, match=f"^{re.escape(str(bad))}: filter_rings: invalid value 0$"):
        load_config(bad)
