"""``python -m bench.speed``: the ``speed`` command alone."""

import typer

from bench.speed.command import speed_command

typer.run(speed_command)
