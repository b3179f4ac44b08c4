"""``loom plan`` (a make-driven farm render) and ``loom farm`` (one target of its Makefile)."""
from __future__ import annotations

import logging

import click

from pipeline.errors import LoomError

from .render import job_options, render_request


@click.command("plan")
@job_options
@click.option("--loom", "loom_command", default=None,
              help="The loom command the recipes run (default: this one; a farm may wrap it, e.g. 'srun loom').")
@click.option("--decide-workers", type=int, default=1, show_default=True,
              help="Worker processes a guided decide recipe traces its photons on (1: in its own process; "
                   "with --photons N the shoot targets trace instead).")
def plan_command(loom_command, decide_workers, **job) -> None:
    """Write OUT/Makefile: a make-driven farm render (make -C OUT -j N) of what `loom render` would make."""
    from pipeline.run.farm import bounds, write_plan
    from pipeline.run.render import prepare_job

    made = prepare_job(render_request(**job))
    path = write_plan(made, loom_command, decide_workers)
    segments, chunks = bounds(made)
    click.echo(f"wrote {path}: up to {segments} segment(s) x {chunks} chunk(s) of frames; "
               f"run: make -C {job['out_dir']} -j N")


@click.command("farm", hidden=True)
@click.argument("step", type=click.Choice(["shoot", "decide", "reconstruct", "frames", "done", "finish"]))
@click.argument("out_dir", type=click.Path(file_okay=False))
@click.argument("numbers", type=int, nargs=-1)
def farm_command(step: str, out_dir: str, numbers: tuple[int, ...]) -> None:
    """One target of a `loom plan` Makefile (pipeline/run/farm.py)."""
    from pipeline.run.farm import step as run_step

    logging.getLogger("pipeline.scene.notices").setLevel(logging.WARNING)  # `loom plan` showed them once

    want = {"shoot": 2, "decide": 1, "reconstruct": 2, "frames": 2, "done": 1, "finish": 0}[step]
    if len(numbers) != want or any(n < 0 for n in numbers):
        raise LoomError(f"{step} takes {want} index(es) >= 0, got {list(numbers)}", field="farm")
    click.echo(run_step(step, out_dir, *numbers))
