"""The long fuzz of pose-graph files: `fuzz_graph_files(n, seed)` runs n malformed g2o / TORO files through what
`vslam graph optimize FILE --out OUT` does (`vslam.app.graph.optimize_graph_file`) and counts the outcomes.

Cases are structure-aware: a small valid graph (planar or 3D, g2o or TORO, sometimes with FIX, comments, RTAB-Map
style PARAMS / landmark records, nanosecond or >= 2^63 ids, a disconnected part) with one to three parts changed.
Half the cases break records (tokens deleted, replaced by odd numbers or text, lines duplicated, swapped or cut,
tags changed, information made singular or indefinite, quaternions zeroed, edges pointed at missing vertices or at
themselves, bytes such as NUL, BOM, CR inserted, the file truncated); the other half stay well formed and make the
graph hard to solve (odometry gaps, vertices missing or isolated, wild false loops, information scaled by 1e+-15 or
nearly singular, values far off). All seeded (`random.Random(seed)`): case k is reproduced from
(seed, k) alone.

Options per case: the defaults, --robust none or --solver isam2 (`case_options`). Outcomes per case: processed (an output written; `non_finite` counts those whose solution is not finite),
typed_error (a ToolkitError; `typed_without_file` counts messages that do not name the input file), traceback (any
other exception: a bug), hang (longer than `hang_seconds`; killed after `kill_seconds`). Each case runs in a worker
process so that a hang inside gtsam can be killed.

    python -m vslam.bench.fuzz_graphs --cases 1000 --seed 0
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import random
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

from odometry.shared.errors import ToolkitError
from vslam.app.graph import optimize_graph_file

OUTCOMES = ("processed", "typed_error", "traceback", "hang")
_INFO2 = [100.0, 0.0, 0.0, 100.0, 0.0, 400.0]
_INFO3 = [100.0, 0, 0, 0, 0, 0, 100.0, 0, 0, 0, 0, 100.0, 0, 0, 0, 400.0, 0, 0, 400.0, 0, 400.0]
_ODD_NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e400", "1e-320", "-0", "0", "+5", "0x10", "1_000",
                "9" * 30, "-9" * 1, "3.", ".5", "1e", "--1", "NaN", "Infinity", "", "abc", "\u0663", "1,5",
                str(2 ** 63), str(2 ** 64), str(-(2 ** 63) - 1), "1.0e+10", "4" * 5000]
_TAGS = ["VERTEX_SE2", "EDGE_SE2", "VERTEX_SE3:QUAT", "EDGE_SE3:QUAT", "VERTEX2", "EDGE2", "VERTEX3", "EDGE3",
         "FIX", "EQUIV", "PARAMS_SE3OFFSET", "VERTEX_XY", "EDGE_SE2_XY", "VERTEX_TRACKXYZ", "EDGE_SE3_PRIOR",
         "VERTEX", "EDGE", "vertex_se2", "#", "VERTEX_SE2\u00a0", "EDGE_SE3:QUATX"]


# ------------------------------------------------------------------------------------------------ generator
def _num(v: float) -> str:
    return repr(round(v, 6))


def base_graph(rng: random.Random) -> str:
    """A small valid graph file: a noisy odometry chain with a few loops, in one of the four record dialects."""
    fmt = rng.choice(["g2o", "toro"])
    dim = rng.choice([2, 2, 3])
    n = rng.randint(2, 25)
    base_id = rng.choice([0, 0, 1, 1_700_000_000_000_000_000, 2 ** 63 - 5, 2 ** 64 + 3, -50])
    step = rng.choice([1, 1, 2, 7])
    ids = [base_id + step * k for k in range(n)]
    if rng.random() < 0.2:
        rng.shuffle(ids)
    x = y = th = 0.0
    lines: list[str] = []
    if rng.random() < 0.3:
        lines.append("# a comment")
    if fmt == "g2o" and dim == 3 and rng.random() < 0.3:
        lines.append("PARAMS_SE3OFFSET 0 0 0 0 0 0 0 1")
    poses = []
    for k in range(n):
        poses.append((x, y, th))
        x += math.cos(th) * 1.0
        y += math.sin(th) * 1.0
        th += rng.uniform(-0.4, 0.4)
    for i, (px, py, pt) in zip(ids, poses):
        lines.append(_vertex(fmt, dim, i, px, py, pt))
    if fmt == "g2o" and rng.random() < 0.3:
        lines.append(f"FIX {ids[0]}")
    pairs = [(k, k + 1) for k in range(n - 1)]
    pairs += [(rng.randrange(n), rng.randrange(n)) for _ in range(rng.randint(0, 4))]
    if n > 6 and rng.random() < 0.15:      # a disconnected second part
        cut = rng.randrange(2, n - 2)
        pairs = [(a, b) for a, b in pairs if (a < cut) == (b < cut)]
    for a, b in pairs:
        if a == b:
            continue
        pa, pb = poses[a], poses[b]
        c, s = math.cos(pa[2]), math.sin(pa[2])
        dx, dy = pb[0] - pa[0], pb[1] - pa[1]
        zx, zy = c * dx + s * dy + rng.gauss(0, 0.02), -s * dx + c * dy + rng.gauss(0, 0.02)
        zt = math.atan2(math.sin(pb[2] - pa[2]), math.cos(pb[2] - pa[2])) + rng.gauss(0, 0.01)
        lines.append(_edge(fmt, dim, ids[a], ids[b], zx, zy, zt))
    if fmt == "g2o" and dim == 2 and rng.random() < 0.2:
        lines += [f"VERTEX_XY {ids[-1] + 1000} 1 1", f"EDGE_SE2_XY {ids[0]} {ids[-1] + 1000} 1 1 10 0 10"]
    if fmt == "toro" and rng.random() < 0.2:
        lines.append(f"EQUIV {ids[0]} {ids[-1]}")
    return "\n".join(lines) + "\n"


def _vertex(fmt: str, dim: int, i: int, x: float, y: float, th: float) -> str:
    if dim == 2:
        return f"{'VERTEX_SE2' if fmt == 'g2o' else 'VERTEX2'} {i} {_num(x)} {_num(y)} {_num(th)}"
    if fmt == "g2o":
        return f"VERTEX_SE3:QUAT {i} {_num(x)} {_num(y)} 0 0 0 {_num(math.sin(th / 2))} {_num(math.cos(th / 2))}"
    return f"VERTEX3 {i} {_num(x)} {_num(y)} 0 0 0 {_num(th)}"


def _edge(fmt: str, dim: int, a: int, b: int, zx: float, zy: float, zt: float) -> str:
    if dim == 2:
        info = " ".join(_num(v) for v in (_INFO2 if fmt == "g2o" else [100.0, 0.0, 100.0, 400.0, 0.0, 0.0]))
        return f"{'EDGE_SE2' if fmt == 'g2o' else 'EDGE2'} {a} {b} {_num(zx)} {_num(zy)} {_num(zt)} {info}"
    info = " ".join(_num(v) for v in _INFO3)
    if fmt == "g2o":
        return (f"EDGE_SE3:QUAT {a} {b} {_num(zx)} {_num(zy)} 0 0 0 {_num(math.sin(zt / 2))} "
                f"{_num(math.cos(zt / 2))} {info}")
    return f"EDGE3 {a} {b} {_num(zx)} {_num(zy)} 0 0 0 {_num(zt)} {info}"


def _mutate_once(lines: list[str], rng: random.Random) -> list[str]:
    if not lines:
        return [rng.choice(_TAGS)]
    k = rng.randrange(len(lines))
    toks = lines[k].split()
    op = rng.randrange(14)
    if op == 0 and toks:                                   # delete a token
        del toks[rng.randrange(len(toks))]
    elif op == 1 and toks:                                 # replace a token by an odd number or text
        toks[rng.randrange(len(toks))] = rng.choice(_ODD_NUMBERS)
    elif op == 2:                                          # duplicate a line
        lines.insert(k, lines[k])
        return lines
    elif op == 3:                                          # swap two lines
        j = rng.randrange(len(lines))
        lines[k], lines[j] = lines[j], lines[k]
        return lines
    elif op == 4:                                          # drop a line (odometry gap, missing vertex)
        del lines[k]
        return lines
    elif op == 5 and toks:                                 # another tag
        toks[0] = rng.choice(_TAGS)
    elif op == 6 and len(toks) > 6:                        # singular / indefinite / asymmetric information
        tail = rng.choice([["0"] * 6, ["-1"] * 6, ["1", "5", "0", "1", "0", "1"], ["1e-300"] * 6])
        toks[-len(tail):] = tail
    elif op == 7 and len(toks) > 8:                        # zero or huge quaternion
        toks[5:9] = rng.choice([["0", "0", "0", "0"], ["1e200", "0", "0", "1"], ["0", "0", "0", "-1"]])
    elif op == 8 and len(toks) > 2:                        # an id no vertex has, or the same id twice
        toks[rng.choice([1, 2])] = rng.choice([str(rng.randrange(10 ** 6, 10 ** 7)), toks[1]])
    elif op == 9 and toks:                                 # extra tokens
        toks += [rng.choice(_ODD_NUMBERS) for _ in range(rng.randint(1, 3))]
    elif op == 10:                                         # cut the line short
        lines[k] = lines[k][:rng.randrange(len(lines[k]) + 1)]
        return lines
    elif op == 11:                                         # junk bytes inside a line
        junk = rng.choice(["\x00", "\ufeff", "\r", "\t", "\x1b[0m", "\u2028", "\ufffd", "#", " # c"])
        pos = rng.randrange(len(lines[k]) + 1)
        lines[k] = lines[k][:pos] + junk + lines[k][pos:]
        return lines
    elif op == 12 and len(toks) > 3:                       # enormous measurement or pose value
        toks[3] = rng.choice(["1e150", "-1e150", "1e15", "3e-310"])
    else:                                                  # a whole line of a random tag and random fields
        lines.insert(k, " ".join([rng.choice(_TAGS)] + [rng.choice(_ODD_NUMBERS[:12] + ["1", "0", "2"])
                                                        for _ in range(rng.randint(0, 31))]))
        return lines
    lines[k] = " ".join(toks)
    return lines


_EDGE_TAGS = ("EDGE_SE2", "EDGE_SE3:QUAT", "EDGE2", "EDGE3")
_VERTEX_TAGS = ("VERTEX_SE2", "VERTEX_SE3:QUAT", "VERTEX2", "VERTEX3")


def _degenerate_once(lines: list[str], rng: random.Random) -> list[str]:
    """A change that keeps every record well formed but makes the graph hard to solve: gaps in the odometry,
    vertices missing or isolated, false loops, extreme or nearly singular information, far-off values."""
    edges = [k for k, ln in enumerate(lines) if ln.split()[:1] and ln.split()[0] in _EDGE_TAGS]
    verts = [k for k, ln in enumerate(lines) if ln.split()[:1] and ln.split()[0] in _VERTEX_TAGS]
    ids = [ln.split()[1] for k, ln in enumerate(lines) if k in verts]
    op = rng.randrange(8)
    if op == 0 and edges:                                  # a gap in the chain (maybe a second component)
        del lines[rng.choice(edges)]
    elif op == 1 and verts:                                # an edge names a vertex with no VERTEX line
        del lines[rng.choice(verts)]
    elif op == 2 and edges:                                # information scaled by 1e-15 .. 1e15
        k = rng.choice(edges)
        t = lines[k].split()
        ninfo = 6 if t[0] in ("EDGE_SE2", "EDGE2") else 21
        f = 10.0 ** rng.uniform(-15, 15)
        t[-ninfo:] = [_num(float(v) * f) if float(v) else "0" for v in t[-ninfo:]]
        lines[k] = " ".join(t)
    elif op == 3 and edges:                                # nearly singular information (PD, condition ~1e14)
        k = rng.choice(edges)
        t = lines[k].split()
        if t[0] in ("EDGE_SE2", "EDGE2"):
            t[-6:] = ["1", "0.99999999999999", "0", "1", "0", "1"] if t[0] == "EDGE_SE2" else \
                ["1", "0.99999999999999", "1", "1", "0", "0"]
        lines[k] = " ".join(t)
    elif op == 4 and edges and len(ids) > 2:               # false loops with wild measurements
        for _ in range(rng.randint(1, 5)):
            t = lines[rng.choice(edges)].split()
            a, b = rng.sample(ids, 2)
            t[1], t[2] = a, b
            t[3] = _num(rng.uniform(-1e3, 1e3))
            lines.append(" ".join(t))
    elif op == 5 and edges:                                # the same edge many times
        lines += [lines[rng.choice(edges)]] * rng.randint(2, 50)
    elif op == 6 and verts:                                # a vertex far away, or an isolated vertex
        t = lines[rng.choice(verts)].split()
        if rng.random() < 0.5:
            t[2] = rng.choice(["1e9", "-1e12", "1e15"])
            lines[verts[ids.index(t[1])]] = " ".join(t)
        else:
            t[1] = str(rng.randrange(10 ** 8, 10 ** 9))
            lines.append(" ".join(t))
    elif edges:                                            # a measurement far off
        k = rng.choice(edges)
        t = lines[k].split()
        t[rng.randrange(3, 6)] = rng.choice(["1e6", "-1e9", "1e12", "3.14159e3"])
        lines[k] = " ".join(t)
    return lines


def malformed_graph(seed: int, index: int) -> bytes:
    """Case `index` of the fuzz with `seed`: a valid small graph with one to three parts broken (see module doc)."""
    rng = random.Random(seed * 1_000_003 + index)
    lines = base_graph(rng).splitlines()
    # half the cases stay well formed and stress the solver, half break the records and stress the reader
    mutate = _degenerate_once if rng.random() < 0.5 else _mutate_once
    for _ in range(rng.choice([1, 1, 2, 3])):
        lines = mutate(lines, rng)
    data = ("\n".join(lines) + "\n").encode("utf-8", errors="surrogatepass")
    r = rng.random()
    if r < 0.05:
        data = data[:rng.randrange(len(data) + 1)]                      # truncated file
    elif r < 0.08:
        data = b"\xef\xbb\xbf" + data                                    # BOM
    elif r < 0.10:
        pos = rng.randrange(len(data) + 1)
        data = data[:pos] + bytes(rng.randrange(256) for _ in range(rng.randint(1, 8))) + data[pos:]
    return data


def case_options(seed: int, index: int) -> dict:
    """The `vslam graph optimize` options of case `index`: the defaults for 60 % of the cases, least squares
    (--robust none: LAGO / chordal start) for 20 %, an iSAM2 pass (--solver isam2) for 20 %."""
    r = random.Random(seed * 1_000_003 + index + 7_777_777).random()
    return {} if r < 0.6 else ({"robust": "none"} if r < 0.8 else {"solver": "isam2"})


# --------------------------------------------------------------------------------------------------- runner
def _worker(conn) -> None:
    warnings.simplefilter("ignore")
    conn.send("ready")                  # imports done: case timings do not include the start-up
    while True:
        job = conn.recv()
        if job is None:
            return
        path, out, options = job
        try:
            run = optimize_graph_file(path, out, **options)
            conn.send(("processed", "" if run.finite else "non_finite"))
        except ToolkitError as exc:
            conn.send(("typed_error", str(exc)))
        except Exception:                                  # noqa: BLE001 - any other exception is what we count
            conn.send(("traceback", traceback.format_exc(limit=6)))


class _Worker:
    def __init__(self, ctx):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child,), daemon=True)
        self.proc.start()
        if not self.conn.poll(300) or self.conn.recv() != "ready":
            raise RuntimeError("the fuzz worker process did not start")

    def stop(self, kill: bool = False) -> None:
        if kill:
            self.proc.kill()
        else:
            try:
                self.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        self.proc.join(5)


def fuzz_graph_files(n: int = 1000, seed: int = 0, hang_seconds: float = 2.0, kill_seconds: float = 30.0,
                     keep_dir: str | Path | None = None) -> dict:
    """Run `n` malformed graphs through `optimize_graph_file`; returns the counts per outcome (OUTCOMES), plus
    `non_finite`, `typed_without_file`, the slowest case's seconds and up to five examples per bad outcome. Case
    files of tracebacks and hangs are copied to `keep_dir` when given."""
    counts = {k: 0 for k in OUTCOMES}
    counts.update(cases=n, seed=seed, non_finite=0, typed_without_file=0, max_seconds=0.0)
    examples: dict[str, list] = {"traceback": [], "hang": [], "typed_without_file": []}
    ctx = mp.get_context("spawn")          # no fork of a process that may hold gtsam / BLAS threads
    work = Path(tempfile.mkdtemp(prefix="vslam-fuzz-graphs-"))
    worker = _Worker(ctx)
    try:
        for k in range(n):
            path = work / f"case{k:05d}.g2o"
            path.write_bytes(malformed_graph(seed, k))
            out = work / "out.g2o"
            t0 = time.perf_counter()
            worker.conn.send((str(path), str(out), case_options(seed, k)))
            if worker.conn.poll(kill_seconds):
                outcome, detail = worker.conn.recv()
            else:
                worker.stop(kill=True)
                worker = _Worker(ctx)
                outcome, detail = "hang", f"killed after {kill_seconds} s"
            dt = time.perf_counter() - t0
            counts["max_seconds"] = max(counts["max_seconds"], round(dt, 3))
            if outcome != "hang" and dt > hang_seconds:
                outcome, detail = "hang", f"{dt:.2f} s ({outcome})"
            counts[outcome] += 1
            if outcome == "processed" and detail == "non_finite":
                counts["non_finite"] += 1
            if outcome == "typed_error" and str(path) not in detail:
                counts["typed_without_file"] += 1
                if len(examples["typed_without_file"]) < 5:
                    examples["typed_without_file"].append((k, detail))
            if outcome in ("traceback", "hang"):
                if len(examples[outcome]) < 5:
                    examples[outcome].append((k, detail[-800:]))
                if keep_dir:
                    Path(keep_dir).mkdir(parents=True, exist_ok=True)
                    shutil.copy(path, Path(keep_dir) / path.name)
            path.unlink()
            out.unlink(missing_ok=True)
    finally:
        worker.stop()
        shutil.rmtree(work, ignore_errors=True)
    counts["examples"] = examples
    return counts


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m vslam.bench.fuzz_graphs", description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=1000, help="number of malformed graph files (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the case generator (default 0)")
    p.add_argument("--hang-seconds", type=float, default=2.0, help="a case slower than this counts as a hang (s)")
    p.add_argument("--keep", metavar="DIR", help="copy the files of tracebacks and hangs here")
    a = p.parse_args(argv)
    counts = fuzz_graph_files(a.cases, a.seed, a.hang_seconds, keep_dir=a.keep)
    print(json.dumps(counts, indent=1, default=str))
    return 0 if counts["traceback"] == 0 and counts["hang"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
