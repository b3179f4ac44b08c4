"""Every tunable parameter of a run, with the paper symbol it implements and its default.

The paper is Myszkowski, Tawara, Akamine, Seidel, *Perception-Guided Global Illumination
Solution for Animation Rendering*, SIGGRAPH 2001. Section numbers below refer
to it. Configs are frozen dataclasses with validation, ``to_dict``/``from_dict`` and a stable
``hash`` that goes into store attributes, task keys and EXR headers.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from .errors import ConfigError

STAGES = ("photons", "collection", "filter", "segments")


def _param(default, stage: str, symbol: str, lo=None, hi=None, *, odd: bool = False, optional: bool = False,
           closed: bool = False):
    """A config field with the stage that reads it, its paper symbol and its valid range. A float's
    lower bound is exclusive unless ``closed`` (integer bounds are always inclusive)."""
    return dataclasses.field(default=default, metadata=dict(stage=stage, symbol=symbol, lo=lo, hi=hi, odd=odd,
                                                            optional=optional, closed=closed))


@dataclass(frozen=True, kw_only=True)
class RenderConfig:
    """Parameters of the spatiotemporal photon processing (§5) and of the element mesh (§4).

    Grouped by the stage that reads them (``STAGES``); :meth:`stage_hash` digests one stage's
    fields, so a stage's stored results are keyed by what they really depend on: changing d_thr
    re-decides segments (pipeline/run/coordinator.py) but keeps the photons, while changing
    element_size or photon_depth refuses the photon store.
    """

    # --- photons: tracing and the element mesh they are bucketed on (§4), pipeline/photons/tracing.py --------
    element_size: float | None = _param(None, "photons", "element size (§4, §5.3)", 0.0, optional=True)
    seed: int = _param(0, "photons", "run seed: Philox key (seed, frame), counter = photon index", 0)
    # Paths end by Russian roulette (§4); this cap is only a safety net for albedo-1 rooms: a
    # photon in a closed room of albedo rho survives it with probability rho^256 (1e-25 at 0.8)
    photon_depth: int = _param(256, "photons", "safety cap on photon hits; Russian roulette ends paths (§4)",
                               1, 1024)

    # --- collection: temporal windows, Condition (1) (§5.1), kernels/temporal.py ------------------
    k_sigma: float = _param(2.0, "collection", "k in mu - k sigma <= x <= mu + k sigma, §5.1 Eq. (1)", 0.0)
    smoothing_frames: int = _param(3, "collection", "frames averaged for mu and x, §5.1", 1, 255, odd=True)
    min_extent: int = _param(3, "collection", "minimal temporal extent in frames, §5.1", 1, 255)
    step_k: float = _param(6.0, "collection", "z of the regional step test: windows stop at an abrupt change "
                           "(pipeline/regional_steps.py)", 0.0)
    step_relative: float = _param(0.1, "collection", "smallest change of a cell's photon rate between two frames "
                                  "that is a step, relative to the larger rate (pipeline/regional_steps.py)", 0.0, 1.0)
    step_levels: int = _param(4, "collection", "cell sizes of the regional step test, from 2x the element size, "
                              "doubling (pipeline/regional_steps.py; 0: off, Condition (1) alone as the paper)", 0, 16)

    # --- filter: adaptive object-space filter (§5.2.5, Volevich et al. 2000), kernels/filter.py -----
    spatial_filter: bool = _param(True, "filter", "Step 5 of §5.2: filter where too few photons were collected")
    filter_photons: float = _param(25.0, "filter", "n_eff below which a vertex is filtered, r = 1/sqrt(n), §5.2.5",
                                   0.0)
    filter_rings: int = _param(3, "filter", "h_max, in element rings over the same surface, §5.2.5", 1, 255)
    filter_z: float = _param(2.5, "filter", "bias test: a ring differing by > z sigma stops h, "
                             "docs/05-estimators.md §1.5", 0.0)
    filter_angle: float = _param(30.0, "filter", "degrees between neighbour normals, docs/05-estimators.md §1.5",
                                 0.0, 180.0)

    # --- segments: the adjustment loops of §5.2 (pipeline/segments/decisions.py, pipeline/run/coordinator.py) -----
    fmax_initial: int = _param(15, "segments", "F_max of the first segment, §5.2.1 and §6", 0, 510)
    fmax_step: int = _param(15, "segments", "F_max growth per step of §5.2.2 (15, 30, 44: the paper's values)",
                            1, 510)
    fmax_cap: int = _param(44, "segments", "largest F_max, §5.2.2 (44: the paper's largest, §6 Table 1)", 0, 510)
    p_thr: float = _param(0.40, "segments", "p_thr, share of elements collecting all F_max/2 frames, §5.2.2",
                          0.0, 1.0)
    e_max: float = _param(0.05, "segments", "E_max, energy-based error after pooling, §5.2.1 Eq. (2)", 0.0)
    pilot_photons: int = _param(10_000, "segments", "photons of the pilot run at K, §5.2.1 (the paper's 10,000)",
                                100, 1 << 30)
    n_frame_min: int = _param(1_000, "segments", "smallest N_frame the pilot may choose, §5.2.1", 1, 1 << 30)
    # Where no N_frame up to the cap makes the halves' difference invisible, the loop stops here and the
    # segment is reported capped (docs/07-segments.md §7)
    n_frame_max: int = _param(1_280_000, "segments", "largest N_frame of the doubling loop, reported when hit, "
                              "§5.2.3", 1, 1 << 30)
    d_thr: float = _param(0.03, "segments", "d_thr, share of AQM pixels above 1 JND, §5.2.3", 0.0, 1.0)
    aqm_size: int = _param(256, "segments", "AQM input size in pixels, §6", 16, 4096)
    # An end frame's windows reach one way only, so it collects about half the photons of a frame
    # inside the animation (docs/07-segments.md §2)
    end_photons: float = _param(2.0, "segments", "N_frame factor for frames within F_max/2 of an animation "
                                "end, which lack one neighbour segment, §5.2 (1: none)", 1.0, 64.0, closed=True)

    def __post_init__(self) -> None:
        for f in fields(self):
            value, m = getattr(self, f.name), f.metadata
            if value is None and m["optional"]:
                continue
            kind = type(f.default) if f.default is not None else float
            numeric = isinstance(value, (int, float)) and not (isinstance(value, bool) and kind is not bool)
            ok = numeric and (kind is not int or float(value).is_integer()) and value == value
            if ok and kind is not bool:
                lo, hi = m["lo"], m["hi"]
                # float lower bounds are exclusive (> 0) unless closed, integer ones inclusive
                ok = ((lo is None or (value > lo if kind is float and not m["closed"] else value >= lo))
                      and (hi is None or value <= hi) and (not m["odd"] or int(value) % 2 == 1))
            if not ok:
                raise ConfigError(f"invalid value {value!r}", field=f.name)
        if self.fmax_initial > self.fmax_cap:
            raise ConfigError(f"fmax_initial {self.fmax_initial} exceeds fmax_cap {self.fmax_cap}",
                              field="fmax_initial")

    @classmethod
    def stage_fields(cls, stage: str) -> tuple[str, ...]:
        if stage not in STAGES:
            raise ValueError(f"unknown stage {stage!r}")
        return tuple(f.name for f in fields(cls) if f.metadata["stage"] == stage)

    def stage_hash(self, stage: str) -> str:
        """Digest of the fields one stage reads."""
        return stable_digest({name: getattr(self, name) for name in self.stage_fields(stage)})

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "RenderConfig":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown parameter(s) {', '.join(unknown)}", field="config")
        return cls(**data)

    def replace(self, **changes: Any) -> "RenderConfig":
        return dataclasses.replace(self, **changes)

    @property
    def hash(self) -> str:
        """Stable 16-hex-digit digest of every field (sorted JSON)."""
        return stable_digest(self.to_dict())

    def photon_hash(self, element_size: float) -> str:
        """Digest of what the photons depend on: the resolved element size and the tracer's
        settings (the seed is stored on its own). The photon store is keyed by it, so changing
        k_sigma or d_thr reuses the photons while changing element_size refuses the store."""
        return stable_digest({"element_size": float(element_size), "photon_depth": self.photon_depth})


def stable_digest(data: dict) -> str:
    """16 hex digits of SHA-256 over sorted JSON: the same settings give the same digest anywhere."""
    blob = json.dumps(data, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def load_config(path: str | Path) -> dict:
    """The RenderConfig fields of a JSON file (an object); one-line errors name the file."""
    try:
        data = json.loads(open(path, encoding="utf-8").read(), parse_constant=lambda c: math.nan)
    except OSError as err:
        raise ConfigError(f"cannot read: {err.strerror}", field=str(path)) from None
    except ValueError as err:
        raise ConfigError(f"not JSON: {err}", field=str(path)) from None
    if not isinstance(data, dict):
        raise ConfigError("must be a JSON object of RenderConfig fields", field=str(path))
    try:
        RenderConfig.from_dict(data)
    except ConfigError as err:
        raise ConfigError(err.reason, field=f"{path}: {err.field}") from None
    return data
