"""Rows of `vslam bench graph`: one solve each (graph, policy, fraction, seed, method), resumable, in N processes.

A row is the unit of work and of storage. `RowStore` keeps the rows of one `--out` JSON file and rewrites the file
atomically after every finished row, so a killed run loses at most the rows in flight; a rerun with the same file
skips every row already there with the same code version (`code_version`: a hash of the pose-graph package, the
bench's graph modules and the default parameters). Rows of another version are kept and flagged "stale" in the
tables, or redone with `--redo-stale`. Each row also records the git commit it ran on.

Workers (`--jobs N`) are spawned processes; each holds at most one graph in memory (the last one it solved), and
the parent orders the work graph by graph, so memory stays at N graphs.
"""
from __future__ import annotations

import functools
import hashlib
import json
import multiprocessing
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from graph import GraphParams
from graph.labels import coincidentally_true, count_false_loops
from vslam.bench import graph_methods
from vslam.bench.graph_data import TUNING_GRAPHS, TUNING_SEEDS, datasets, load
from vslam.bench.graph_g2o import PeerCrashed
from vslam.bench.graph_outliers import add_false_loops
from vslam.bench.graph_reference import REF_MAX_ITERATIONS, REF_TOL, converged_reference
from vslam.bench.results import write_json
from vslam.evaluation.metrics import umeyama

_ROOT = Path(__file__).resolve().parents[2]
# what a row's numbers depend on: the pose-graph package, the methods and peers, the false loops, the graph list;
# not the bookkeeping of rows and tables (editing those must not make finished rows stale)
_VERSIONED = ("graph", "vslam/bench/graph_methods.py", "vslam/bench/graph_g2o.py", "vslam/bench/graph_outliers.py",
              "vslam/bench/graph_data.py")


@dataclass(frozen=True)
class Task:
    graph: str
    policy: str          # "-" on the clean graph
    fraction: float
    seed: int
    method: str

    @property
    def key(self) -> tuple:
        return (self.graph, self.policy, round(self.fraction, 6), int(self.seed), self.method)


def row_key(row: dict) -> tuple:
    return (row["graph"], row["policy"], round(float(row["fraction"]), 6), int(row["seed"]), row["method"])


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """Hash of the code, default parameters and reference settings a row's result depends on (16 hex digits)."""
    h = hashlib.sha256()
    for rel in _VERSIONED:
        p = _ROOT / rel
        files = sorted(p.rglob("*.py")) if p.is_dir() else [p]
        for f in files:
            h.update(str(f.relative_to(_ROOT)).encode())
            h.update(f.read_bytes())
    h.update(json.dumps([GraphParams().to_dict(), REF_TOL, REF_MAX_ITERATIONS], sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """The commit the code runs from, with "+dirty" when the versioned files differ from it; "unknown" off git."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=_ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", *_VERSIONED], cwd=_ROOT).returncode != 0
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def ate(ref: np.ndarray, est: np.ndarray, dim: int) -> float:
    """RMSE of positions after the rigid alignment of est onto ref."""
    x, y = est[:, :dim], ref[:, :dim]
    r, t, _ = umeyama(x, y)
    return float(np.sqrt(np.mean(np.sum((y - (x @ r.T + t)) ** 2, axis=1))))


class RowStore:
    """The rows and graph heads of one output JSON file; every `add` rewrites the file atomically."""

    def __init__(self, path: str | Path, meta: dict | None = None):
        self.path = Path(path)
        self.meta = dict(meta or {})
        self.rows: dict[tuple, dict] = {}
        self.graphs: dict[str, dict] = {}
        if self.path.exists():
            d = json.loads(self.path.read_text())
            self.graphs = graph_heads(d)
            for r in d.get("rows", []):
                self.rows[row_key(r)] = r

    def done(self, task: Task, version: str) -> bool:
        r = self.rows.get(task.key)
        return r is not None and r.get("version") == version

    def present(self, task: Task) -> bool:
        return task.key in self.rows

    def add(self, row: dict) -> None:
        self.rows[row_key(row)] = row
        self.save()

    def set_graph(self, head: dict) -> None:
        self.graphs[head["graph"]] = head
        self.save()

    def save(self) -> None:
        write_json(self.path, {"benchmark": "graph", **self.meta, "tuning_graphs": TUNING_GRAPHS,
                               "tuning_seeds": TUNING_SEEDS, "graphs": list(self.graphs.values()),
                               "rows": list(self.rows.values())})


def graph_heads(d: dict) -> dict[str, dict]:
    """Graph heads of a bench JSON (a list in every version of the file)."""
    return {g["graph"]: g for g in d.get("graphs", [])}


def plan(names: Iterable[str], nodes: dict[str, int], policies, fractions, seeds, methods,
         peer_max: int) -> list[Task]:
    """Every row of a selection, graph by graph; the clean graph once (policy "-", the first seed)."""
    out = []
    for g in names:
        for policy in policies:
            for f in fractions:
                if f == 0 and policy != policies[0]:
                    continue                       # the clean graph is the same for every policy
                for seed in (seeds if f > 0 else seeds[:1]):
                    for m in methods:
                        if m in graph_methods.PEERS_LIMITED and f > 0 and nodes[g] > peer_max:
                            continue
                        out.append(Task(g, policy if f > 0 else "-", float(f), int(seed), m))
    return out


def priority_order(tasks: list[Task], methods: list[str]) -> list[Task]:
    """Tasks reordered so that a run cut short has the most telling rows: method by method in the order asked
    (ours first), and within a method the clean graph, then 50 %, 30 %, 10 %, the stretch rows last, each over
    every graph. Workers then load graphs more often (one in memory each, as before)."""
    graphs = list(dict.fromkeys(t.graph for t in tasks))
    policies = list(dict.fromkeys(t.policy for t in tasks))

    def rank(t: Task) -> tuple:
        f = t.fraction
        fr = 0.0 if f == 0 else (1.0 + (0.5 - f) if f <= 0.5 else 10.0 + f)    # 0, 50, 30, 10 %, then 70, 80
        return (methods.index(t.method), fr, graphs.index(t.graph), policies.index(t.policy), t.seed)
    return sorted(tasks, key=rank)


@functools.lru_cache(maxsize=1)
def _graph(name: str, ref_dir: str | None):
    ds = next(d for d in datasets() if d.name == name)
    data, gt = load(ds)
    ref = converged_reference(name, ds.path, data, Path(ref_dir) if ref_dir else None)
    return data, gt, ref


def head(name: str, ref_dir: str | None) -> dict:
    """What a graph's tables say about it: size, reference, converged and default plain LM on the clean graph."""
    ds = next(d for d in datasets() if d.name == name)
    data, gt, ref = _graph(name, ref_dir)
    truth = gt if gt is not None else ref.poses
    plain = graph_methods.plain_lm(data)
    return {"graph": name, "nodes": data.num_nodes, "loops": data.num_loops, "dim": data.dim,
            "reference": "ground truth" if gt is not None else "converged clean optimum",
            "ref_ate": ate(truth, ref.poses, data.dim), "ref_iterations": ref.iterations, "ref_s": ref.seconds,
            "clean_ate": ate(truth, plain.poses, data.dim), "clean_ate_opt": ate(ref.poses, plain.poses, data.dim),
            "clean_s": plain.seconds, "note": ds.note}


def run_task(task: Task, ref_dir: str | None, jobs: int = 1, peer_timeout: float = 0.0) -> dict:
    """One row: the method on the graph with the task's false loops. A crashed peer or a failing method gives a
    row with status "crashed" / "failed" and the reason, never an exception (the run goes on); a peer of
    `graph_methods.PEERS_LIMITED` still running after `peer_timeout` seconds (0: no limit) is stopped and its row
    has status "timeout"."""
    data, gt, ref = _graph(task.graph, ref_dir)
    dd, false = add_false_loops(data, task.policy, task.fraction, task.seed) if task.fraction > 0 else \
        (data, np.zeros(data.num_loops, bool))
    row = {"graph": task.graph, "policy": task.policy, "fraction": task.fraction, "seed": task.seed,
           "method": task.method, "false_loops": int(false.sum()),
           "tuning": task.graph in TUNING_GRAPHS and task.seed in TUNING_SEEDS,
           "version": code_version(), "commit": git_commit(), "jobs": jobs}
    try:
        if peer_timeout and task.method in graph_methods.PEERS_LIMITED:
            run = _run_with_timeout(task.method, dd, peer_timeout)
        else:
            run = graph_methods.METHODS[task.method](dd)
    except PeerTimeout as e:
        return {**row, "status": "timeout", "timeout_s": float(peer_timeout), "error": str(e)}
    except PeerCrashed as e:
        return {**row, "status": "crashed", "error": str(e)}
    except Exception as e:          # noqa: BLE001 - one failing row must not end a run of hours
        return {**row, "status": "failed", "error": f"{type(e).__name__}: {e}"}
    truth = gt if gt is not None else ref.poses
    out = {**row, "status": "ok", "ate": ate(truth, run.poses, data.dim), "ate_opt": ate(ref.poses, run.poses,
           data.dim), "s": run.seconds,
           "true_kept": float(run.kept[~false].mean()) if (~false).any() else 1.0,
           "false_rejected": float((~run.kept[false]).mean()) if false.any() else 1.0}
    if false.any():
        # injected loops that state the truth are counted apart; the 99 % target is on the wrong ones (graph.labels)
        c = count_false_loops(false, run.kept, coincidentally_true(dd, truth))
        out.update(coincidental=c.coincidental, coincidental_kept=c.coincidental_kept, wrong=c.wrong,
                   wrong_kept=c.wrong_kept, wrong_rejected=c.wrong_rejected)
    return out


class PeerTimeout(RuntimeError):
    """A peer did not finish within the run's --peer-timeout: its row says so, the run goes on."""


def _peer_child(method: str, data, conn) -> None:
    try:
        run = graph_methods.METHODS[method](data)
        conn.send(("ok", (run.poses, run.kept, run.seconds)))
    except Exception as e:          # noqa: BLE001 - reported by the parent as the row's failure
        conn.send(("failed", f"{type(e).__name__}: {e}"))


def _run_with_timeout(method: str, data, seconds: float) -> graph_methods.MethodRun:
    """The peer in a spawned child, stopped after `seconds` (gtsam's GNC has no time limit of its own and ran over
    30 minutes on parking-garage at 50 % random false loops; the process is the unit that can be stopped)."""
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_peer_child, args=(method, data, child))
    proc.start()
    child.close()
    try:
        if not parent.poll(seconds):
            raise PeerTimeout(f"{method} did not finish in {seconds:.0f} s")
        status, payload = parent.recv()
    except EOFError as e:
        raise PeerCrashed(f"{method} child died (exit code {proc.exitcode})") from e
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
    if status != "ok":
        raise RuntimeError(payload)
    return graph_methods.MethodRun(*payload)


def _run_star(args) -> dict:
    return run_task(*args)


def execute(tasks: list[Task], ref_dir: str | None, jobs: int, on_row: Callable[[dict], None],
            peer_timeout: float = 0.0) -> None:
    """Run `tasks` (in order with one job, else in `jobs` spawned processes) and hand each row to `on_row` as it
    finishes. `peer_timeout` (seconds, 0: none) needs one job: pool workers cannot start the peer's child."""
    if jobs <= 1:
        for t in tasks:
            on_row(run_task(t, ref_dir, 1, peer_timeout))
        return
    if peer_timeout:
        raise ValueError("--peer-timeout runs each peer in a child process and needs --jobs 1")
    ctx = multiprocessing.get_context("spawn")      # no fork after gtsam's threads started
    with ctx.Pool(jobs) as pool:
        for row in _unordered(pool, [(t, ref_dir, jobs) for t in tasks]):
            on_row(row)


def _unordered(pool, items) -> Iterator[dict]:
    yield from pool.imap_unordered(_run_star, items, chunksize=1)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)
