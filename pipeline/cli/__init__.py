"""The ``loom`` command: thin click wrappers over the pipeline; no algorithms live here.

One module per command group: scene.py (``scene``, ``info``), render.py (``shoot``, ``render``,
``segments``, ``report``), farm.py (``plan``, the hidden ``farm``), aqm.py (``aqm``), bench.py
(``bench ...``, over the measuring code in pipeline/benchmarks/). Every
:class:`~pipeline.errors.LoomError` becomes one line on stderr and exit status 2.
"""
from __future__ import annotations

import logging
import sys

import click

from kernels.context import DeviceError
from pipeline.errors import LoomError

from .aqm import aqm_command
from .bench import bench
from .farm import farm_command, plan_command
from .render import render_command, report_command, segments_command, shoot_command
from .scene import info_command, scene_command


class _LoomGroup(click.Group):
    """Turns user-input errors, ours and click's usage errors alike, into one line and exit 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except LoomError as err:
            click.echo(f"loom: error: {err}", err=True)
            sys.exit(2)
        except DeviceError as err:  # the machine, not the input or a bug: one line too
            click.echo(f"loom: error: OpenCL: {err}", err=True)
            sys.exit(2)

    def main(self, *args, **kwargs):
        if kwargs.get("standalone_mode", True) is False:
            return super().main(*args, **kwargs)
        try:
            return super().main(*args, standalone_mode=False, **kwargs)
        except click.UsageError as err:
            if isinstance(err, getattr(click.exceptions, "NoArgsIsHelpError", ())) and err.ctx is not None:
                click.echo(err.ctx.get_help())  # a bare `loom` or `loom bench` asks for help
                sys.exit(0)
            where = f"{err.ctx.command_path}: " if err.ctx is not None else ""
            click.echo(f"loom: error: {where}{err.format_message()} (see --help)", err=True)
            sys.exit(err.exit_code)
        except click.ClickException as err:
            click.echo(f"loom: error: {err.format_message()}", err=True)
            sys.exit(err.exit_code)
        except click.exceptions.Abort:
            click.echo("loom: aborted", err=True)
            sys.exit(1)


@click.group(cls=_LoomGroup)
@click.version_option(package_name="photonloom")
def main() -> None:
    """photonloom: perception-guided global illumination for animations."""
    logging.basicConfig(level=logging.WARNING, format="loom: %(levelname)s: %(message)s")
    logging.getLogger("pipeline.scene.notices").setLevel(logging.INFO)  # default camera and lights chosen


for _command in (scene_command, info_command, shoot_command, render_command, segments_command, report_command,
                 plan_command, farm_command, aqm_command, bench):
    main.add_command(_command)
