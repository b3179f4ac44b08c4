"""Every tunable parameter of a run, with the paper symbol it implements and its default.

The paper is Myszkowski, Tawara, Akamine, Seidel, *Perception-Guided Global Illumination
Solution for Animation Rendering*, SIGGRAPH 2001. Section numbers below refer
to it. Each stage has a frozen config of the fields it reads, validated when made: PhotonConfig
(§4), CollectionConfig (§5.1), FilterConfig (§5.2.5), SegmentConfig (§5.2); RenderConfig composes
them. Stored results are keyed by the digests of the stages they depend on (the segment decisions
by the collection, filter and segment configs' ``hash``, the photon store by
``PhotonConfig.photon_hash``), so changing d_thr re-decides segments (pipeline/run/coordinator.py)
but keeps the photons, while changing element_size or photon_depth refuses the photon store.
``--config`` files are flat (``{"d_thr": 0.02}``): RenderConfig's ``from_dict``/``to_dict``
translate, and ``RenderConfig.hash`` (store attributes, task keys, EXR headers) digests that flat
form.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Self

from .errors import ConfigError

# The AQM works on images scaled down to 256 pixels (§6); the metric and the segments read it here
AQM_SIZE = 256


def _param(default, symbol: str, lo=None, hi=None, *, odd: bool = False, optional: bool = False,
           closed: bool = False):
    """A config field with its paper symbol and its valid range. A float's lower bound is exclusive
    unless ``closed`` (integer bounds are always inclusive)."""
    return dataclasses.field(default=default, metadata=dict(symbol=symbol, lo=lo, hi=hi, odd=odd,
                                                            optional=optional, closed=closed))


def _check_fields(config: Any) -> None:
    """Every field of a stage config against its metadata; a one-line ConfigError names the first
    that is out of range."""
    for f in fields(config):
        value, m = getattr(config, f.name), f.metadata
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


@dataclass(frozen=True, kw_only=True)
class _Stage:
    """What every stage config shares: its fields checked when made, their digest, and replace."""

    def __post_init__(self) -> None:
        _check_fields(self)

    @property
    def hash(self) -> str:
        """Digest of this stage's fields: what its stored results are keyed by."""
        return stable_digest(dataclasses.asdict(self))

    def replace(self, **changes: Any) -> Self:
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, kw_only=True)
class PhotonConfig(_Stage):
    """Photon tracing and the element mesh the photons are bucketed on (§4), pipeline/photons/tracing.py."""

    element_size: float | None = _param(None, "element size (§4, §5.3)", 0.0, optional=True)
    seed: int = _param(0, "run seed: Philox key (seed, frame), counter = photon index", 0)
    # Paths end by Russian roulette (§4); this cap is only a safety net for albedo-1 rooms: a
    # photon in a closed room of albedo rho survives it with probability rho^256 (1e-25 at 0.8)
    photon_depth: int = _param(256, "safety cap on photon hits; Russian roulette ends paths (§4)", 1, 1024)

    def photon_hash(self, element_size: float) -> str:
        """Digest of what the photons depend on: the resolved element size and the tracer's
        settings (the seed is stored on its own). The photon store is keyed by it, so changing
        k_sigma or d_thr reuses the photons while changing element_size refuses the store."""
        return stable_digest({"element_size": float(element_size), "photon_depth": self.photon_depth})


@dataclass(frozen=True, kw_only=True)
class CollectionConfig(_Stage):
    """The temporal windows, Condition (1) (§5.1), kernels/temporal.py and pipeline/collection/."""

    k_sigma: float = _param(2.0, "k in mu - k sigma <= x <= mu + k sigma, §5.1 Eq. (1)", 0.0)
    smoothing_frames: int = _param(3, "frames averaged for mu and x, §5.1", 1, 255, odd=True)
    min_extent: int = _param(3, "minimal temporal extent in frames, §5.1", 1, 255)
    step_k: float = _param(6.0, "z of the regional step test: windows stop at an abrupt change "
                           "(pipeline/collection/regional_steps.py)", 0.0)
    step_relative: float = _param(0.1, "smallest change of a cell's photon rate between two frames that is a "
                                  "step, relative to the larger rate (pipeline/collection/regional_steps.py)",
                                  0.0, 1.0)
    step_levels: int = _param(4, "cell sizes of the regional step test, from 2x the element size, doubling "
                              "(pipeline/collection/regional_steps.py; 0: off, Condition (1) alone as the paper)",
                              0, 16)


@dataclass(frozen=True, kw_only=True)
class FilterConfig(_Stage):
    """The adaptive object-space filter (§5.2.5, Volevich et al. 2000), kernels/filter.py."""

    spatial_filter: bool = _param(True, "Step 5 of §5.2: filter where too few photons were collected")
    filter_photons: float = _param(25.0, "n_eff below which a vertex is filtered, r = 1/sqrt(n), §5.2.5", 0.0)
    filter_rings: int = _param(3, "h_max, in element rings over the same surface, §5.2.5", 1, 255)
    filter_z: float = _param(2.5, "bias test: a ring differing by > z sigma stops h, docs/05-estimators.md §1.5",
                             0.0)
    filter_angle: float = _param(30.0, "degrees between neighbour normals, docs/05-estimators.md §1.5",
                                 0.0, 180.0)


@dataclass(frozen=True, kw_only=True)
class SegmentConfig(_Stage):
    """The adjustment loops of §5.2: pipeline/segments/decisions.py, pipeline/run/coordinator.py."""

    fmax_initial: int = _param(15, "F_max of the first segment, §5.2.1 and §6", 0, 510)
    fmax_step: int = _param(15, "F_max growth per step of §5.2.2 (15, 30, 44: the paper's values)", 1, 510)
    fmax_cap: int = _param(44, "largest F_max, §5.2.2 (44: the paper's largest, §6 Table 1)", 0, 510)
    p_thr: float = _param(0.40, "p_thr, share of elements collecting all F_max/2 frames, §5.2.2", 0.0, 1.0)
    e_max: float = _param(0.05, "E_max, energy-based error after pooling, §5.2.1 Eq. (2)", 0.0)
    pilot_photons: int = _param(10_000, "photons of the pilot run at K, §5.2.1 (the paper's 10,000)", 100, 1 << 30)
    n_frame_min: int = _param(1_000, "smallest N_frame the pilot may choose, §5.2.1", 1, 1 << 30)
    # Where no N_frame up to the cap makes the halves' difference invisible, the loop stops here and the
    # segment is reported capped (docs/07-segments.md §7)
    n_frame_max: int = _param(1_280_000, "largest N_frame of the doubling loop, reported when hit, §5.2.3",
                              1, 1 << 30)
    d_thr: float = _param(0.03, "d_thr, share of AQM pixels above 1 JND, §5.2.3", 0.0, 1.0)
    aqm_size: int = _param(AQM_SIZE, "AQM input size in pixels, §6", 16, 4096)
    # An end frame's windows reach one way only, so it collects about half the photons of a frame
    # inside the animation; so do the frames beside a lighting step (docs/07-segments.md §2, §8)
    end_photons: float = _param(2.0, "N_frame factor for frames within F_max/2 of an animation end, which "
                                "lack one neighbour segment, §5.2, or of a lighting step (1: none)", 1.0, 64.0,
                                closed=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.fmax_initial > self.fmax_cap:
            raise ConfigError(f"fmax_initial {self.fmax_initial} exceeds fmax_cap {self.fmax_cap}",
                              field="fmax_initial")


@dataclass(frozen=True, kw_only=True)
class RenderConfig:
    """Parameters of the spatiotemporal photon processing (§5) and of the element mesh (§4): one
    config per stage, each read by that stage alone."""

    photons: PhotonConfig = dataclasses.field(default_factory=PhotonConfig)
    collection: CollectionConfig = dataclasses.field(default_factory=CollectionConfig)
    filter: FilterConfig = dataclasses.field(default_factory=FilterConfig)
    segments: SegmentConfig = dataclasses.field(default_factory=SegmentConfig)

    @staticmethod
    def _stages() -> dict[str, type[_Stage]]:
        """Each part's name and its stage config type, in the order of the flat form."""
        return {f.name: f.default_factory for f in fields(RenderConfig)}

    def to_dict(self) -> dict:
        """The flat form: every stage's fields under their own names (the ``--config`` file's)."""
        return {k: v for name in self._stages() for k, v in dataclasses.asdict(getattr(self, name)).items()}

    @classmethod
    def from_dict(cls, data: dict) -> RenderConfig:
        """A config from the flat form; an unknown name is refused."""
        stages = cls._stages()
        owner = {f.name: name for name, stage in stages.items() for f in fields(stage)}
        unknown = sorted(set(data) - set(owner))
        if unknown:
            raise ConfigError(f"unknown parameter(s) {', '.join(unknown)}", field="config")
        return cls(**{name: stage(**{k: v for k, v in data.items() if owner[k] == name})
                      for name, stage in stages.items()})

    def replace(self, **changes: Any) -> RenderConfig:
        return dataclasses.replace(self, **changes)

    @property
    def hash(self) -> str:
        """Stable 16-hex-digit digest of every field (sorted JSON of the flat form)."""
        return stable_digest(self.to_dict())


def stable_digest(data: dict) -> str:
    """16 hex digits of SHA-256 over sorted JSON: the same settings give the same digest anywhere."""
    blob = json.dumps(data, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def load_config(path: str | Path) -> dict:
    """The flat RenderConfig fields of a JSON file (an object); one-line errors name the file."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"), parse_constant=lambda c: math.nan)
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
