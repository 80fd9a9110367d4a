"""Decode frames in a background thread while the pipeline works on the previous one.

OpenCV releases the GIL while decoding, so on two cores decoding overlaps processing. The queue is bounded,
so memory stays bounded whatever the sequence length; frames come out in order. `lazy_frames` is the same stream
undecoded, for a consumer that needs only some frames' pixels.
"""
from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from vslam.sequence import Sequence


@dataclass(frozen=True)
class DecodedFrame:
    index: int
    timestamp: float
    image: np.ndarray | None     # None when the file could not be read
    error: str                   # why (empty when the image is fine)
    decode_seconds: float


@dataclass(frozen=True)
class LazyFrame:
    """A frame read only when `image()` is called (None when the file cannot be read)."""
    seq: Sequence
    index: int
    error: str = ""
    decode_seconds: float = 0.0

    @property
    def timestamp(self) -> float:
        return float(self.seq.timestamps[self.index])

    def image(self) -> np.ndarray | None:
        return read_frame(self.seq, self.index, gray=True).image


def read_frame(seq: Sequence, i: int, gray: bool = True) -> DecodedFrame:
    """Frame `i` decoded now; an unreadable file gives image None and the reason (the frame is lost, not the run)."""
    t0 = time.perf_counter()
    try:
        img, err = seq.image(i, gray=gray), ""
    except (ValueError, OSError) as exc:   # ImageReadError and friends
        img, err = None, str(exc)
    return DecodedFrame(i, float(seq.timestamps[i]), img, err, time.perf_counter() - t0)


def lazy_frames(seq: Sequence, start: int = 0, stop: int | None = None) -> Iterator[LazyFrame]:
    stop = len(seq) if stop is None else min(stop, len(seq))
    return (LazyFrame(seq, i) for i in range(start, stop))


def prefetch(seq: Sequence, gray: bool = True, depth: int = 8, start: int = 0, stop: int | None = None
             ) -> Iterator[DecodedFrame]:
    stop = len(seq) if stop is None else min(stop, len(seq))
    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    done = threading.Event()

    def work() -> None:
        for i in range(start, stop):
            if done.is_set():
                return
            item = read_frame(seq, i, gray)
            while not done.is_set():
                try:
                    q.put(item, timeout=0.1)
                    break
                except queue.Full:
                    continue
        q.put(None)

    th = threading.Thread(target=work, name="vslam-decode", daemon=True)
    th.start()
    try:
        while True:
            item = q.get()
            if item is None:
                return
            yield item
    finally:
        done.set()
        th.join(timeout=5)
