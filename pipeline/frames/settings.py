"""What a frame's pixels depend on besides the scene, photons and seed: ``RenderSettings``, which
``loom render`` takes and the render's Job carries (pipeline/segments/job.py)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

from pipeline.errors import LoomError

from .shutter import MAX_SHUTTER
from .tonemap import ToneMapping

MAX_SIDE = 16384


@dataclass(frozen=True, kw_only=True)
class RenderSettings:
    """What a frame's pixels depend on besides the scene, photons and seed."""

    width: int = 640
    height: int = 480
    # jittered camera samples per pixel; the one default of loom render's --spp and of the benchmarks that
    # render as loom render does (pipeline/cli/render.py RENDER_SPP; 8: docs/10-sampling.md §2)
    spp: int = 8
    reflection_depth: int = 4  # mirror/glossy reflections followed per camera path
    area_samples: int = 2  # area-light (or sky) samples per diffuse hit (scenes with emissive triangles or a sky)
    # share of the frame interval the shutter is open, centred on the frame's time: motion blur
    # (pipeline/frames/shutter.py); 0 is an instant, 0.5 film's 180-degree shutter
    shutter: float = 0.0
    tonemap: ToneMapping = field(default_factory=ToneMapping)

    def __post_init__(self) -> None:
        for name, lo, hi in (("width", 1, MAX_SIDE), ("height", 1, MAX_SIDE), ("spp", 1, 4096),
                             ("reflection_depth", 0, 64), ("area_samples", 1, 256)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                flag = "--resolution" if name in ("width", "height") else f"--{name.replace('_', '-')}"
                raise LoomError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}", field=flag)
        if isinstance(self.shutter, bool) or not isinstance(self.shutter, (int, float)) \
                or not 0.0 <= self.shutter <= MAX_SHUTTER:
            raise LoomError(f"shutter must be a number in [0, {MAX_SHUTTER:g}], got {self.shutter!r}",
                            field="--shutter")

    def to_dict(self) -> dict:
        """Plain JSON values (the tone mapping as its own dict), for plan.json and the report."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> RenderSettings:
        return cls(**{**data, "tonemap": ToneMapping(**data["tonemap"])})
