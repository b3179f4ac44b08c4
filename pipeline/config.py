"""Every tunable parameter of a run, with the paper symbol it implements and its default.

The paper is Myszkowski, Tawara, Akamine, Seidel, *Perception-Guided Global Illumination
Solution for Animation Rendering*, SIGGRAPH 2001 (``shared/paper``). Section numbers below refer
to it. Configs are frozen dataclasses with validation, ``to_dict``/``from_dict`` and a stable
``hash`` that goes into store attributes, task keys and EXR headers.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, fields

from .errors import ConfigError


@dataclass(frozen=True, kw_only=True)
class RenderConfig:
    """Parameters of the spatiotemporal photon processing (§5) and of the element mesh (§4)."""

    # --- element mesh (§4, §5.3) -----------------------------------------------------------
    element_size: float | None = None  # max element edge, scene units; None: the scene's own (§4, §5.3)

    # --- temporal photon processing (§5.1) -------------------------------------------------
    k_sigma: float = 2.0  # k in Condition (1): mu - k*sigma <= x <= mu + k*sigma, §5.1
    smoothing_frames: int = 3  # frames averaged for mu and x, §5.1
    min_extent: int = 3  # minimal temporal extent in frames, always collected, §5.1

    # --- adaptive spatial filter (§5.2.5, Volevich et al. 2000; kernels/filter.py) ----------
    filter_photons: float = 25.0  # n_eff below which a vertex is filtered; target r = 1/sqrt(n), §5.2.5
    filter_rings: int = 3  # h_max: largest support, in element rings over the same surface, §5.2.5
    filter_z: float = 2.5  # bias test: stop growing h where a ring differs by > z sigma, dept.md §1.5
    filter_angle: float = 30.0  # degrees; neighbours' normals within this of the vertex's, dept.md §1.5

    # --- segment adjustment loops (§5.2) ---------------------------------------------------
    fmax_initial: int = 15  # initial F_max, frames in a segment, §5.2.1 and §6
    p_thr: float = 0.40  # p_thr, share of elements whose photons stay valid, §5.2.2
    e_max: float = 0.05  # E_max, target energy-based error after temporal pooling, §5.2.1 Eq. (2)
    d_thr: float = 0.03  # d_thr, AQM share of pixels with visible difference, §5.2.3
    aqm_size: int = 256  # AQM input size in pixels, §6

    # --- photon tracing (§4) ---------------------------------------------------------------
    seed: int = 0  # run seed; photon i of frame f draws Philox words keyed by (seed, f), counter i
    max_depth: int = 8  # maximum photon bounces before termination

    def __post_init__(self) -> None:
        checks = {
            "element_size": self.element_size is None or self.element_size > 0,
            "k_sigma": self.k_sigma > 0,
            "smoothing_frames": self.smoothing_frames >= 1 and self.smoothing_frames % 2 == 1,
            "min_extent": self.min_extent >= 1,
            "filter_photons": self.filter_photons > 0,
            "filter_rings": 1 <= self.filter_rings <= 255,
            "filter_z": self.filter_z > 0,
            "filter_angle": 0 < self.filter_angle <= 180,
            "fmax_initial": self.fmax_initial >= 0,
            "p_thr": 0.0 <= self.p_thr <= 1.0,
            "e_max": self.e_max > 0,
            "d_thr": 0.0 <= self.d_thr <= 1.0,
            "aqm_size": self.aqm_size >= 16,
            "seed": self.seed >= 0,
            "max_depth": self.max_depth >= 1,
        }
        for name, ok in checks.items():
            if not ok:
                raise ConfigError(f"invalid value {getattr(self, name)!r}", field=name)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "RenderConfig":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown parameter(s) {', '.join(unknown)}", field="config")
        return cls(**data)

    def replace(self, **changes) -> "RenderConfig":
        return dataclasses.replace(self, **changes)

    @property
    def hash(self) -> str:
        """Stable 16-hex-digit digest of every field (sorted JSON)."""
        return stable_digest(self.to_dict())

    def photon_hash(self, element_size: float) -> str:
        """Digest of what the photons depend on: the resolved element size and the tracer's
        settings (the seed is stored on its own). The photon store is keyed by it, so changing
        k_sigma or d_thr reuses the photons while changing element_size refuses the store."""
        return stable_digest({"element_size": float(element_size), "max_depth": self.max_depth})


def stable_digest(data: dict) -> str:
    """16 hex digits of SHA-256 over sorted JSON: the same settings give the same digest anywhere."""
    blob = json.dumps(data, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]
