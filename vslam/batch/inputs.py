"""What `vslam batch INPUTS...` means: each input is a sequence (a folder any reader of `vslam.io` opens, or a
video), a folder of sequences, a glob, or a manifest CSV (one sequence per row, optional per-row overrides).

Manifest CSV columns (header row required):

    sequence    path of the sequence, relative to the CSV's folder or absolute (required)
    name        output folder name under --out (default: the sequence's folder or file name)
    overrides   dotted KEY=VALUE assignments separated by ';', e.g. `loops.mode=5; vo.max_features=300`,
                applied on top of the batch's configuration with PipelineConfig.with_overrides (optional)

Names must be unique: the outputs go to OUT/<name>/. Sequences found in several inputs with the same folder name are
told apart by their parent folders (`robot1__night3`).
"""
from __future__ import annotations

import csv
import glob
import os
from dataclasses import dataclass
from pathlib import Path

from vslam.batch.errors import BatchError
from vslam.io.public_formats import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS, is_kitti, is_tum_rgbd
from vslam.io.sequence_dir import is_sequence_dir

MANIFEST_COLUMNS = ("sequence", "name", "overrides")
GLOB_CHARS = set("*?[")


@dataclass(frozen=True)
class BatchItem:
    """One sequence of a batch: its output name, absolute path, and per-sequence config overrides."""
    name: str
    sequence: str                     # absolute path: workers and `vslam run` record the same string
    overrides: tuple[str, ...] = ()
    source: str = ""                  # where it was named (file:line for a manifest row), for error messages


def is_sequence(path: Path) -> bool:
    """A path one of the sequence readers opens: a video file, a sequence directory, TUM RGB-D, KITTI, or a folder
    holding images directly."""
    if path.is_file():
        return path.suffix.lower() in VIDEO_EXTENSIONS
    if not path.is_dir():
        return False
    if is_sequence_dir(path) or is_tum_rgbd(path) or is_kitti(path):
        return True
    return any(p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file() for p in path.iterdir())


def _folder_of_sequences(path: Path) -> list[Path]:
    return sorted(p for p in path.iterdir() if not p.name.startswith(".") and is_sequence(p))


def parse_overrides(text: str) -> tuple[str, ...]:
    """`loops.mode=5; vo.max_features=300` -> ("loops.mode=5", "vo.max_features=300")."""
    return tuple(s.strip() for s in text.split(";") if s.strip())


def read_manifest_csv(path: str | Path) -> list[tuple[Path, str | None, tuple[str, ...], str]]:
    """(sequence path, name or None, overrides, "file:line") per row of a manifest CSV."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise BatchError(path, f"not UTF-8 text: {exc}") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise BatchError(path, "empty manifest: expected a header row with a 'sequence' column", line=1)
    header = [h.strip() for h in rows[0]]
    for h in header:
        if h not in MANIFEST_COLUMNS:
            raise BatchError(path, f"unknown column (expected {', '.join(MANIFEST_COLUMNS)})", line=1, field=h)
    if "sequence" not in header:
        raise BatchError(path, "no 'sequence' column in the header", line=1)
    out = []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) > len(header):
            raise BatchError(path, f"{len(row)} values for {len(header)} columns", line=lineno)
        rec = dict(zip(header, [c.strip() for c in row] + [""] * (len(header) - len(row))))
        if not rec["sequence"]:
            raise BatchError(path, "empty sequence path", line=lineno, field="sequence")
        seq = Path(rec["sequence"]).expanduser()
        if not seq.is_absolute():
            seq = path.parent / seq
        name = rec.get("name") or None
        if name is not None and (os.sep in name or name in (".", "..") or name.startswith(".")):
            raise BatchError(path, f"{name!r} is not a plain folder name", line=lineno, field="name")
        out.append((seq, name, parse_overrides(rec.get("overrides", "")), f"{path}:{lineno}"))
    return out


def _expand(arg: str) -> list[tuple[Path, str | None, tuple[str, ...], str]]:
    p = Path(arg).expanduser()
    if p.suffix.lower() == ".csv" and p.is_file():
        return read_manifest_csv(p)
    if GLOB_CHARS & set(arg) and not p.exists():
        hits = sorted(glob.glob(os.path.expanduser(arg)))
        if not hits:
            raise BatchError(None, f"{arg!r} matched nothing")
        return [(Path(h), None, (), arg) for h in hits if not Path(h).name.startswith(".")]
    if p.is_dir() and not is_sequence(p):
        found = _folder_of_sequences(p)
        if not found:
            raise BatchError(p, "neither a sequence nor a folder holding sequences")
        return [(s, None, (), arg) for s in found]
    # a sequence, or a path that does not open: kept, so that it is reported as that sequence's failure
    return [(p, None, (), arg)]


def _unique_names(paths: list[Path]) -> list[str]:
    """The last path component, extended with parent folders (joined by '__') until every name is unique."""
    depth = [1] * len(paths)
    while True:
        names = ["__".join(p.parts[-d:]) if d <= len(p.parts) else "__".join(p.parts) for p, d in zip(paths, depth)]
        names = [n.lstrip(os.sep).replace(os.sep, "__") or "root" for n in names]
        seen: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            seen.setdefault(n, []).append(i)
        clashes = [ix for ix in seen.values() if len(ix) > 1]
        grown = False
        for ix in clashes:
            for i in ix:
                if depth[i] < len(paths[i].parts):
                    depth[i] += 1
                    grown = True
        if not clashes or not grown:
            return names


def resolve_inputs(inputs: list[str]) -> list[BatchItem]:
    """Every sequence the inputs name, in order, each once (by absolute path), with unique output names."""
    if not inputs:
        raise BatchError(None, "no inputs: give sequence folders, a folder of them, a glob or a manifest CSV")
    rows, seen = [], set()
    for arg in inputs:
        for seq, name, overrides, source in _expand(arg):
            key = str(seq.resolve())
            if key in seen:
                continue
            seen.add(key)
            rows.append((Path(key), name, overrides, source))
    auto = _unique_names([p for p, name, _, _ in rows if name is None])
    it = iter(auto)
    items = [BatchItem(name if name is not None else next(it), str(p), overrides, source)
             for p, name, overrides, source in rows]
    names: dict[str, BatchItem] = {}
    for item in items:
        if item.name in names:
            raise BatchError(None, f"two sequences would write to the same output folder {item.name!r}: "
                                   f"{names[item.name].sequence} ({names[item.name].source}) and {item.sequence} "
                                   f"({item.source}); give them distinct 'name's in a manifest CSV")
        names[item.name] = item
    return items
