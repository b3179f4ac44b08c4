"""The light a file without any light is rendered with: a directional sun and a uniform sky.

Decision: many glTF files, from sample collections and DCC exports, carry no light;
refusing them (``--light none`` still does) leaves a new user with nothing. The default is a
clear day in the file's units (docs/03-conventions.md §1: radiometric, no 683 lm/W), with a clear day's values:
1000 W/m^2 of direct sun at normal incidence and about 130 W/m^2 of diffuse sky on a horizontal
surface. The level matters because tone mapping is absolute (pipeline/frames/tonemap.py, Ward 1994,
one unit of radiance = ``nits_per_unit`` cd/m^2): at daylight levels a sunlit white surface
shows near display white and shadows stay readable, where a dim rig would look like dusk.

* the **sun**, a ``directional`` light of irradiance ``SUN_IRRADIANCE x SUN_COLOR`` on a surface
  facing it, from azimuth ``SUN_AZIMUTH`` (degrees from +Z towards +X) and elevation
  ``SUN_ELEVATION``: front-left and above, so a model facing +Z (glTF's front) is lit on its
  front and top and casts its shadow behind it, away from the default camera
  (pipeline/scene/default_camera.py looks from the front-right);
* the **sky** (pipeline/scene/sky.py), radiance ``SKY_ZENITH`` from the upper hemisphere (bluish;
  pi x its mean is the diffuse horizontal irradiance, a sixth of the total) and, from the lower hemisphere,
  the radiance of an endless ground of albedo ``GROUND_ALBEDO`` under that sun and sky, so the
  undersides of floating objects are not black.

Both are emitters the photon tracer samples (they cast colour bleeding) and the compositor
samples (shadow rays); the sky is also the background of rays that leave the scene.
"""
from __future__ import annotations

import numpy as np

from .lights import Light, LightDef
from .sky import Sky, direction_from

SUN_IRRADIANCE = 1000.0
SUN_COLOR = (1.0, 0.95, 0.88)
SUN_AZIMUTH = -45.0
SUN_ELEVATION = 50.0
SKY_ZENITH = (32.0, 40.0, 54.0)
GROUND_ALBEDO = 0.1


def default_sun() -> Light:
    """The default sun as a placed directional light (no node: index -1)."""
    definition = LightDef(name="default sun", kind="directional", color=SUN_COLOR, intensity=SUN_IRRADIANCE)
    return Light(definition, -1, np.zeros(3), -direction_from(SUN_AZIMUTH, SUN_ELEVATION))


def default_sky() -> Sky:
    """The default sky: SKY_ZENITH above; below, an endless Lambertian ground of GROUND_ALBEDO lit
    by the sun and the sky above it, radiance albedo x (E_sun sin(elevation) + pi L_zenith) / pi."""
    zenith = np.asarray(SKY_ZENITH, np.float64)
    horizontal = SUN_IRRADIANCE * np.asarray(SUN_COLOR) * np.sin(np.radians(SUN_ELEVATION)) + np.pi * zenith
    ground = GROUND_ALBEDO * horizontal / np.pi
    return Sky(zenith=tuple(float(v) for v in zenith), ground=tuple(float(v) for v in ground))


def describe_default_lights() -> str:
    """One line for notices and ``loom info``."""
    sky = default_sky()
    return (f"default sun (irradiance {SUN_IRRADIANCE:g} x {SUN_COLOR} from azimuth {SUN_AZIMUTH:g} deg, "
            f"elevation {SUN_ELEVATION:g} deg) and uniform sky (radiance {_rgb(sky.zenith)} above the horizon, "
            f"{_rgb(sky.ground)} below)")


def _rgb(v) -> str:
    return "(" + ", ".join(f"{c:.3g}" for c in v) + ")"
