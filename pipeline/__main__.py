"""``python -m pipeline`` is the ``loom`` command."""
from .cli import main

main(prog_name="loom")
