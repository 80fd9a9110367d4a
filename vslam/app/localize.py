"""Kidnapped-robot localisation in a visual memory (vocabulary-tree bag of words) from image folders
(`vslam localize build / query / eval`).

Folders are image folders or sequence directories (frames.csv); images are named by their path relative to the
folder (see `vslam.io.image_folder`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from loops.vocab import NoFeaturesError, VisualMemory, VocabParams, evaluate
from vslam.errors import VslamError
from vslam.evaluation.place_recognition import RANKING_HEADER, write_csv, write_report
from vslam.io.image_folder import list_images, read_image
from vslam.io.truth_csv import read_truth


@dataclass(frozen=True)
class BuiltMemory:
    memory: VisualMemory
    path: Path
    seconds: float

    def summary(self) -> str:
        return (f"{self.memory.describe()}\nbuilt in {self.seconds:.1f} s -> {self.path} "
                f"({self.path.stat().st_size / 1e6:.2f} MB)")


def build_memory(memory_dir: str | Path, params: VocabParams, out: str | Path | None = None) -> BuiltMemory:
    """Build a visual memory from the key images of a folder and save it to `out` (default
    ./<folder>.<descriptor>.vmem)."""
    items = list_images(memory_dir)
    t0 = time.perf_counter()
    memory = VisualMemory.build((read_image(p) for _, p in items), [n for n, _ in items], params)
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
                    out: str | Path) -> str:
    """Build a memory from the key folder, query it with every image of the query folder, score the rankings
    against TRUTH.csv and write the report files into `out` (see `write_report`). Returns report.md's text."""
    keys = list_images(memory_dir)
    queries = list_images(queries_dir)
    key_names, query_names = [n for n, _ in keys], [n for n, _ in queries]
    truth = read_truth(truth_csv, query_names, key_names)
    if not truth:
        raise VslamError(f"{truth_csv}: no ground-truth rows")
    memory = VisualMemory.build((read_image(p) for _, p in keys), key_names, params)
    ev = evaluate(memory, ((n, read_image(p), None) for n, p in queries), truth)
    out = Path(out)
    write_report(out, ev, memory, title=f"{Path(memory_dir).name} vs {Path(queries_dir).name}")
    return (out / "report.md").read_text()
