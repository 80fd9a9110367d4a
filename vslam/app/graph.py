"""Pose-graph files (g2o / TORO) through the back end (`vslam graph`): optimise one and write it with every vertex
id kept, or describe one."""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from graph import GraphParams, optimize, read_graph, write_graph
from graph.errors import GraphError
from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.config import parse_assignments, read_mapping

LABELS_HEADER = "edge,from,to,inlier,weight,r2"


def describe_graph(data) -> str:
    """'N vertices (SE(2)...), M edges: K odometry, L loops' for a read graph."""
    kind = "SE(2)" if data.dim == 2 else "SE(3)"
    no_guess = int((~data.has_pose).sum())
    return (f"{data.num_nodes} vertices ({kind}{f', {no_guess} without a guess' if no_guess else ''}), "
            f"{data.num_edges} edges: {data.num_edges - data.num_loops} odometry, {data.num_loops} loops")


def graph_file_info(path: str | Path) -> str:
    """What `vslam graph info` prints: the counts, and the fixed vertices when the file fixes any."""
    data = read_graph(path)
    lines = [f"{path}: {describe_graph(data)}"]
    if len(data.fixed):
        lines.append(f"fixed vertices: {', '.join(str(i) for i in data.fixed.tolist())}")
    return "\n".join(lines)


@dataclass(frozen=True)
class GraphRun:
    """An optimised graph file: the report lines and whether every pose came out finite."""
    lines: list[str]
    finite: bool
    warnings: tuple[str, ...] = ()    # what the reader and solver warned about (skipped records, disconnected parts)


def graph_params(preset: str = "default", config: str | Path | None = None,
                 overrides: list[str] | tuple[str, ...] = ()) -> GraphParams:
    """The preset, then a config file's settings, then KEY=VALUE assignments. Keys are GraphParams' own
    (`robust.support_window`, `solver.lm_max_iterations`); a pipeline config's `graph:` section and `graph.`-prefixed
    keys are read the same way, so one file serves `vslam run` and `vslam graph optimize`."""
    params = GraphParams.preset(preset)
    if config is not None:
        params = GraphParams.from_dict(_graph_section(read_mapping(config)), str(config), base=params)
    if overrides:
        params = GraphParams.from_dict(_graph_section(parse_assignments(overrides, "--set")), "--set", base=params)
    return params


def _graph_section(d: dict) -> dict:
    inner = d.get("graph")
    if isinstance(inner, dict):
        rest = {k: v for k, v in d.items() if k != "graph"}
        return {**rest, **inner}
    return d


def optimize_graph_file(path: str | Path, out: str | Path, preset: str = "default", solver: str | None = None,
                        robust: str | None = None, init: str | None = None, tum: str | Path | None = None,
                        labels: str | Path | None = None, params: GraphParams | None = None) -> GraphRun:
    """Optimise a g2o / TORO file with `params` (default: the GraphParams preset) and write `out` (same ids, edge
    order, information and comments); optionally the trajectory as TUM (timestamps = vertex ids) and one CSV row per
    loop. `solver`, `robust`, `init` override the params' methods."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = read_graph(path)
        try:
            res = optimize(data, params if params is not None else GraphParams.preset(preset), solver=solver,
                           robust=robust, init=init)
        except GraphError as exc:         # the solver's errors do not know the file: name it
            raise GraphError(f"{path}: {exc}") from exc
    write_graph(out, data, res.poses)
    lines = [f"{path}: {describe_graph(data)}",
             f"solver {res.solver}, robust {res.robust}, init {res.init}",
             f"cost {res.initial_cost:.6g} -> {res.final_cost:.6g}  ({res.iterations} iterations"
             f"{f', {res.gnc_iterations} GNC steps' if res.gnc_iterations else ''})",
             f"time {res.seconds:.3f} s (initial guess {res.init_seconds:.3f} s)",
             f"loops kept {res.loops_kept} / rejected {res.loops_rejected}",
             f"wrote {out}"]
    if tum:
        res.write_tum(tum)
        lines.append(f"wrote {tum}")
    if labels:
        rows = [LABELS_HEADER]
        for e, ok, w, r2 in zip(res.loop_edges.tolist(), res.loop_inlier.tolist(), res.loop_weight.tolist(),
                                res.loop_residual.tolist()):
            rows.append(f"{e},{int(data.edge_from[e])},{int(data.edge_to[e])},{int(ok)},{w:.6g},{r2:.6g}")
        atomic_write_text(labels, "\n".join(rows) + "\n")
        lines.append(f"wrote {labels}")
    return GraphRun(lines, bool(np.all(np.isfinite(res.poses))), tuple(str(w.message) for w in caught))
