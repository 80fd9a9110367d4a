"""Decode frames in a background thread while the pipeline works on the previous one.

OpenCV releases the GIL while decoding, so on two cores decoding overlaps processing. The queue is bounded,
so memory stays bounded whatever the sequence length; frames come out in order.
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


def prefetch(seq: Sequence, gray: bool = True, depth: int = 8, start: int = 0, stop: int | None = None
             ) -> Iterator[DecodedFrame]:
    stop = len(seq) if stop is None else min(stop, len(seq))
    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    done = threading.Event()

    def work() -> None:
        for i in range(start, stop):
            if done.is_set():
                return
            t0 = time.perf_counter()
            try:
                img, err = seq.image(i, gray=gray), ""
            except (ValueError, OSError) as exc:   # ImageReadError and friends: the frame is lost, not the run
                img, err = None, str(exc)
            item = DecodedFrame(i, float(seq.timestamps[i]), img, err, time.perf_counter() - t0)
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
