"""The root of every error the toolkit raises on bad input.

Each package has its own root below it (`odometry.errors.OdometryError`, `loops.errors.LoopsError`,
`graph.errors.GraphError`, `vslam.errors.VslamError`); errors of this shared layer (a malformed TUM file, a bad
configuration value) derive from `ToolkitError` directly. Every one is also a `ValueError`, so code written against
plain ValueErrors keeps working. The command line reports these (and `OSError`) as one line naming the file, line
and field; anything else is a bug and shows its traceback.
"""
from __future__ import annotations


class ToolkitError(ValueError):
    """Bad input: a file, a value or a combination of settings the toolkit cannot use. The message says which."""


class ConfigError(ToolkitError):
    """A configuration key or value that cannot be used; the message names the file and the dotted key."""
