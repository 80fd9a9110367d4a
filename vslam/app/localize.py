"""Kidnapped-robot localisation in a visual memory (vocabulary-tree bag of words) from image folders
(`vslam localize build / query / eval`).

Folders are image folders or sequence directories (frames.csv); images are named by their path relative to the
folder (see `vslam.io.image_folder`).
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from loops.vocab import NoFeaturesError, VisualMemory, VocabParams, evaluate
from vslam.app.outdir import LOCALIZE_EVAL_OUTPUTS, prepare_out_dir
from vslam.errors import SkippedInputWarning, VslamError
from vslam.evaluation.place_recognition import RANKING_HEADER, write_csv, write_report
from vslam.io.image_folder import list_images, read_image
from vslam.io.truth_csv import read_truth


@dataclass(frozen=True)
class BuiltMemory:
    memory: VisualMemory
    path: Path
    seconds: float

    @property
    def skipped_keys(self) -> list[str]:
        """Key images kept without descriptors (no features or unreadable): they never match."""
        return [self.memory.key_names[i] for i in self.memory.featureless]

    def summary(self) -> str:
        text = (f"{self.memory.describe()}\nbuilt in {self.seconds:.1f} s -> {self.path} "
                f"({self.path.stat().st_size / 1e6:.2f} MB)")
        return text + "".join(f"\n{line}" for line in skipped_lines(self.memory))


def skipped_lines(memory: VisualMemory) -> list[str]:
    """One line counting and naming the key images without descriptors, or none."""
    names = [memory.key_names[i] for i in memory.featureless]
    if not names:
        return []
    return [f"{len(names)} of {len(memory)} key images have no features or could not be read (kept as keys "
            f"that never match): {', '.join(names)}"]


def readable_images(items: Sequence[tuple[str, Path]], what: str = "key image",
                    unreadable: list[str] | None = None) -> Iterator[np.ndarray | None]:
    """The images in order; an unreadable one (missing, truncated, corrupt) is None, with a warning naming it
    (and its name appended to `unreadable`): one bad photograph must not cost the whole memory."""
    for name, path in items:
        try:
            yield read_image(path)
        except (OSError, ValueError) as exc:    # ImageReadError is a ValueError
            warnings.warn(SkippedInputWarning(f"{what} {name} skipped: {exc}"), stacklevel=2)
            if unreadable is not None:
                unreadable.append(name)
            yield None


def _build(items: Sequence[tuple[str, Path]], params: VocabParams) -> VisualMemory:
    unreadable: list[str] = []
    memory = VisualMemory.build(readable_images(items, unreadable=unreadable), [n for n, _ in items], params)
    for i in memory.featureless:
        name = memory.key_names[i]
        if name not in unreadable:
            warnings.warn(SkippedInputWarning(f"key image {name} has no {params.descriptor.value} features "
                                              "(blank?): kept as a key that never matches"), stacklevel=2)
    return memory


def build_memory(memory_dir: str | Path, params: VocabParams, out: str | Path | None = None,
                 skip_bad_frames: bool = False) -> BuiltMemory:
    """Build a visual memory from the key images of a folder and save it to `out` (default
    ./<folder>.<descriptor>.vmem). Key images without features or unreadable are kept as keys that never match,
    with a warning; `skip_bad_frames` also accepts a frames.csv listing missing files (strict by default)."""
    items = list_images(memory_dir, check_images="none" if skip_bad_frames else "exists")
    t0 = time.perf_counter()
    memory = _build(items, params)
    seconds = time.perf_counter() - t0
    path = Path(out) if out else Path(f"{Path(memory_dir).resolve().name}.{params.descriptor.value}.vmem")
    memory.save(path)
    return BuiltMemory(memory, path, seconds)


def query_memory(memory_file: str | Path, images: Sequence[str | Path], top: int = 5, csv: str | Path | None = None,
                 echo: Callable[[str], None] = lambda line: None) -> list[tuple[str, int, str, float]]:
    """Rank the key images of a memory file for each query image (files, or folders of them): one line per query
    with its `top` key images, through `echo`; every ranking as (query, rank, key, score) rows, also to `csv`."""
    memory = VisualMemory.load(memory_file)
    items = []
    for spec in images:
        p = Path(spec)
        items += list_images(p) if p.is_dir() else [(p.name, p)]
    rows = []
    for name, path in items:
        image = read_image(path)
        t0 = time.perf_counter()
        try:
            ranking = memory.query(image, name=name)
        except NoFeaturesError as exc:
            echo(f"{name}: {exc}")
            continue
        ms = (time.perf_counter() - t0) * 1e3
        best = ", ".join(f"{memory.key_names[k]} ({s:.3f})" for k, s in zip(ranking.keys[:top], ranking.scores[:top]))
        echo(f"{name} [{ms:.1f} ms]: {best or 'no candidate key image'}")
        rows += [(name, i + 1, memory.key_names[k], float(s)) for i, (k, s) in enumerate(zip(ranking.keys,
                                                                                           ranking.scores))]
    if csv:
        write_csv(csv, RANKING_HEADER, rows)
    return rows


def evaluate_memory(memory_dir: str | Path, queries_dir: str | Path, truth_csv: str | Path, params: VocabParams,
                    out: str | Path, skip_bad_frames: bool = False, overwrite: bool = False) -> str:
    """Build a memory from the key folder, query it with every image of the query folder, score the rankings
    against TRUTH.csv and write the report files into `out` (see `write_report`). Returns report.md's text, with
    a line naming the key images kept without features (see `build_memory`); an unreadable query is a miss."""
    check = "none" if skip_bad_frames else "exists"
    keys = list_images(memory_dir, check_images=check)
    queries = list_images(queries_dir, check_images=check)
    key_names, query_names = [n for n, _ in keys], [n for n, _ in queries]
    truth = read_truth(truth_csv, query_names, key_names)
    if not truth:
        raise VslamError(f"{truth_csv}: no ground-truth rows")
    out = prepare_out_dir(out, LOCALIZE_EVAL_OUTPUTS, overwrite)
    memory = _build(keys, params)
    ev = evaluate(memory, ((n, img, None) for (n, _), img in zip(queries, readable_images(queries, "query image"))), truth)
    write_report(out, ev, memory, title=f"{Path(memory_dir).name} vs {Path(queries_dir).name}")
    return (out / "report.md").read_text() + "".join(f"\n{line}" for line in skipped_lines(memory))
