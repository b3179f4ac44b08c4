"""``loom scene`` (write a built-in scene) and ``loom info`` (summarise a scene file)."""
from __future__ import annotations

import click

from pipeline.scene import read_scene

CAMERA_HELP = ("Camera or camera-node name, or auto: frame the whole animation (pipeline/scene/default_camera.py). "
               "Default: the first camera, auto when the file has none.")
ANIMATION_HELP = ("The animation that plays (by name). Default: the file's first; every animation plays that "
                  "animates no node an earlier one does, so clips of one character play one at a time.")
VARIANT_HELP = ("The material variant to render (KHR_materials_variants, by name; `loom info` lists them). "
                "Default: each primitive's own material.")
ENVIRONMENT_HELP = ("An equirectangular (HDRI) radiance map lighting the scene from every direction, EXR or HDR "
                    "(pipeline/scene/environment.py), in place of the default sun and sky.")
LIGHT_HELP = ("auto: a file without any light is lit by a default sun and sky (pipeline/scene/default_lights.py); "
              "none: refuse it.")


@click.command("scene")
@click.argument("name")
@click.option("-o", "--output", required=True, help="The .glb (or .gltf) to write; folders are made.")
def scene_command(name: str, output: str) -> None:
    """Write the built-in scene NAME (room, atrium, cornell, static) as a glTF file."""
    from pipeline.scene.builtin import write_builtin

    path = write_builtin(name, output)
    click.echo(f"wrote {path}")


@click.command("info")
@click.argument("scene_file", type=click.Path(dir_okay=False))
@click.option("--camera", default=None, help=CAMERA_HELP)
@click.option("--element-size", type=float, default=None, help="Element edge bound (default: the scene's).")
@click.option("--light", type=click.Choice(["auto", "none"]), default="auto", show_default=True, help=LIGHT_HELP)
@click.option("--animation", default=None, help=ANIMATION_HELP)
@click.option("--variant", default=None, help=VARIANT_HELP)
@click.option("--environment", default=None, type=click.Path(dir_okay=False), help=ENVIRONMENT_HELP)
@click.option("--environment-strength", type=float, default=1.0, show_default=True,
              help="Multiplies the environment map's radiance.")
@click.option("--environment-rotation", type=float, default=0.0, show_default=True,
              help="Turns the environment map about +Y, degrees counter-clockwise seen from above.")
def info_command(scene_file: str, camera: str | None, element_size: float | None, light: str,
                 animation: str | None, variant: str | None, environment: str | None,
                 environment_strength: float, environment_rotation: float) -> None:
    """Summarise SCENE_FILE: timeline, geometry, elements, lights, materials, cameras, needs."""
    from pipeline.scene.environment import load_environment
    from pipeline.scene.summary import describe

    env = None if environment is None else load_environment(environment, environment_strength, environment_rotation)
    scene = read_scene(scene_file, camera=camera, light=light, animation=animation, variant=variant, environment=env)
    for line in describe(scene, element_size):
        click.echo(line)
