"""The ``loom`` command: thin click wrappers over the pipeline; no algorithms live here.

Every :class:`~pipeline.errors.LoomError` becomes one line on stderr and exit status 2.
"""
from __future__ import annotations

import logging
import sys

import click

from .errors import LoomError


class _LoomGroup(click.Group):
    """Turns user-input errors into a one-line message and a non-zero exit."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except LoomError as err:
            click.echo(f"loom: error: {err}", err=True)
            sys.exit(2)


@click.group(cls=_LoomGroup)
@click.version_option(package_name="photonloom")
def main() -> None:
    """photonloom: perception-guided global illumination for animations."""
    logging.basicConfig(level=logging.WARNING, format="loom: %(levelname)s: %(message)s")


@main.command("scene")
@click.argument("name")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The .glb (or .gltf) to write.")
def scene_command(name: str, output: str) -> None:
    """Write the built-in scene NAME (room, atrium, cornell, static) as a glTF file."""
    from .scene.builtin import write_builtin

    path = write_builtin(name, output)
    click.echo(f"wrote {path}")


@main.command("info")
@click.argument("scene_file", type=click.Path(dir_okay=False))
@click.option("--camera", default=None, help="Camera or camera-node name (default: the first camera).")
@click.option("--element-size", type=float, default=None, help="Element edge bound (default: the scene's).")
def info_command(scene_file: str, camera: str | None, element_size: float | None) -> None:
    """Summarise SCENE_FILE: timeline, geometry, elements, lights, materials, cameras, needs."""
    from .scene import Scene
    from .scene.summary import describe

    scene = Scene.load(scene_file, camera=camera)
    for line in describe(scene, element_size):
        click.echo(line)


@main.group()
def bench() -> None:
    """Benchmarks (speed is measured here, never in tests)."""

from .cli_aqm import aqm_command, bench_aqm  # noqa: E402
main.add_command(aqm_command, "aqm")
bench.add_command(bench_aqm, "aqm")
