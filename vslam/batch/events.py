"""What an engine reports while a batch runs; the orchestrator turns it into manifest updates and progress."""
from __future__ import annotations

from typing import Protocol


class EngineEvents(Protocol):
    def started(self, name: str, attempt: int) -> None:
        """A sequence was handed to a worker (attempt counts from 1)."""

    def progress(self, name: str, done: int, total: int) -> None:
        """Frames done in a running sequence (engines that can see it)."""

    def finished(self, outcome: dict) -> None:
        """A sequence's outcome (see `vslam.batch.task.process_sequence`), final: no further retry."""


def lost_worker_outcome(name: str, attempts: int, reason: str) -> dict:
    """The outcome of a sequence whose worker died on its last allowed attempt."""
    return {"name": name, "status": "failed", "attempt": attempts, "seconds": 0.0,
            "error": f"worker lost on attempt {attempts} of {attempts}: {reason}"}
