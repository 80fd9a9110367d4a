"""The root of the errors `odometry` raises on bad input (see `odometry.shared.errors`)."""
from __future__ import annotations

from odometry.shared.errors import ToolkitError


class OdometryError(ToolkitError):
    """Bad input to visual odometry or wheel/gyro fusion: the message names the stream, file or field."""
