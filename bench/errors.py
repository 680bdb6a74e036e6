"""User errors of the benchmark: mistakes in the command line or its inputs.

The CLI turns any :class:`UserError` into one line on stderr and exit code 2. This module imports
nothing heavy, so that the CLI can report a bad flag without loading the simulator.
"""

from __future__ import annotations

__all__ = ["UserError"]


class UserError(ValueError):
    """A mistake the user can fix; the message names the file, line, key or flag."""
