"""Stand-ins for the recognition contract in loop-detector tests."""
from __future__ import annotations

from loops.recognition import Ranked


class SamePlace:
    """Every stored key looks the same: retrieval returns all eligible keys, newest first."""

    def __init__(self):
        self.keys = []

    def observe(self, image):
        return image

    def add(self, key, obs):
        self.keys.append(key)

    def query(self, obs, top=None, among=None):
        keys = self.keys[:among if among is not None else len(self.keys)]
        return [Ranked(k, 1.0) for k in reversed(keys)][:top]

    def __len__(self):
        return len(self.keys)
