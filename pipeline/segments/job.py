"""The render a segment belongs to: ``Job``, what the planner (pipeline/segments/planner.py) and the
executors of pipeline/run read of it: scene, store, output folder, frames, settings and hashes."""
from __future__ import annotations

from dataclasses import dataclass, fields

from pipeline.config import RenderConfig
from pipeline.frames.settings import RenderSettings
from pipeline.scene.scene_cache import SceneRef


@dataclass(frozen=True)
class Job:
    """Everything a segment task needs. It travels to workers pickled (frozen dataclasses all
    through); :meth:`to_dict` and :meth:`from_dict` are its plain-JSON form (plan.json, the report)."""

    scene_path: str
    scene_hash: str
    camera: str | None  # the --camera option (None: the scene's first camera)
    camera_name: str  # the camera node rendered from
    element_size: float
    store_url: str
    out_dir: str
    first: int  # first and last frame of the animation the segments cover
    last: int
    selection: tuple  # frames to render (fixed settings may skip frames; guided: first..last)
    settings: RenderSettings  # resolution, spp, reflection depth, area samples, tone mapping
    config: RenderConfig
    render_hash: str  # what a frame's pixels depend on besides its maps and adaptation
    decision_hash: str  # what the segment decisions depend on
    fmax: int  # F_max of the first segment (--fmax or fmax_initial), or of every frame when fixed
    n_photons: int | None  # None: guided (--photons auto); else fixed N_frame
    temporal: str  # adaptive | fixed | off
    single_state: bool  # camera-only motion: every frame shares one photon set
    animation: str | None = None  # the --animation option (None: the file's first clip, pipeline/scene/loader.py)
    variant: str | None = None  # the --variant option (None: the primitives' own materials, pipeline/scene/variants.py)
    environment: tuple[str, float, float] | None = None  # --environment: file, strength, rotation (environment.py)

    @property
    def scene_ref(self) -> SceneRef:
        """The scene as the job's tasks load it."""
        return SceneRef(self.scene_path, self.scene_hash, self.camera, self.element_size, self.animation,
                        self.variant, self.environment)

    def to_dict(self) -> dict:
        return {f.name: (getattr(self, f.name).to_dict() if f.name in ("settings", "config") else getattr(self, f.name))
                for f in fields(self)}

    @classmethod
    def from_dict(cls, data: dict) -> Job:
        environment = data.get("environment")
        return cls(**{**data, "selection": tuple(data["selection"]),
                      "environment": (None if environment is None
                                      else (str(environment[0]), *map(float, environment[1:]))),
                      "settings": RenderSettings.from_dict(data["settings"]),
                      "config": RenderConfig.from_dict(data["config"])})
