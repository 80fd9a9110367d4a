"""The root of the errors `graph` raises on bad input (see `odometry.shared.errors`)."""
from __future__ import annotations

from odometry.shared.errors import ToolkitError


class GraphError(ToolkitError):
    """A pose graph that cannot be read or solved as given: the message names the file and the cause."""
