"""The root of the errors `loops` raises on bad input (see `odometry.shared.errors`)."""
from __future__ import annotations

from odometry.shared.errors import ToolkitError


class LoopsError(ToolkitError):
    """Bad input to place recognition: an image, a descriptor blob, a memory or model file, a pair list."""
