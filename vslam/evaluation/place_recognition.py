"""Reports of visual-memory localisation (loops.vocab): the paper's table layout (Tables 2-7, plus Recall@1/5 and
average precision) and the files of one evaluation (`vslam localize eval`)."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Sequence

from loops.vocab import Evaluation, Summary, VisualMemory
from odometry.shared.atomic_io import atomic_write_text
from vslam.evaluation.plots import plot_pr_curves
from vslam.evaluation.tables import format_table

PAPER_HEADERS = ("Descriptor", "Number of tests", "Correct tests mu1", "Effectiveness mu1 (%)", "Correct tests mu2",
                 "Effectiveness mu2 (%)", "Recall@1", "Recall@5", "AP", "Median time (ms)")
RANKING_HEADER = ("query", "rank", "key", "score")
PER_QUERY_HEADER = ("query", "true_keys", "top1", "top1_score", "mu1", "mu2", "ms", "error")


def format_paper_table(rows: Sequence[tuple[str, Summary]]) -> str:
    """The paper's Tables 2-7 layout (+ Recall@1/5 and average precision); rows = [(label, Summary)]."""
    return format_table(PAPER_HEADERS, [(label, s.n_tests, s.correct_mu1, round(s.eff_mu1, 2),
                                         "n/a" if s.correct_mu2 is None else s.correct_mu2,
                                         "n/a" if s.correct_mu2 is None else round(s.eff_mu2, 2),
                                         round(s.recall1, 3), round(s.recall5, 3),
                                         round(s.average_precision, 3), round(s.median_ms, 1)) for label, s in rows],
                        floatfmt=".4g")


def summary_dict(s: Summary) -> dict:
    """A Summary as JSON-ready numbers."""
    return {"n_tests": s.n_tests, "correct_mu1": s.correct_mu1, "effectiveness_mu1_pct": s.eff_mu1,
            "correct_mu2": s.correct_mu2, "effectiveness_mu2_pct": s.eff_mu2, "recall_at_1": s.recall1,
            "recall_at_5": s.recall5, "average_precision": s.average_precision, "median_ms": s.median_ms}


def write_csv(path: str | Path, header: Sequence[str], rows) -> None:
    """Rows as CSV (floats with 6 significant digits), written atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[f"{v:.6g}" if isinstance(v, float) else v for v in r] for r in rows])
    atomic_write_text(path, buf.getvalue())


def _per_query_rows(ev: Evaluation, key_names: Sequence[str]) -> list[tuple]:
    return [(r.name, ";".join(key_names[k] for k in r.true_keys),
             key_names[int(r.ranking.keys[0])] if len(r.ranking) else "",
             float(r.ranking.scores[0]) if len(r.ranking) else float("nan"), r.mu1, r.mu2, r.seconds * 1e3,
             r.error) for r in ev.results]


def write_report(out: Path, ev: Evaluation, memory: VisualMemory, title: str) -> dict:
    """ranking.csv, per_query.csv, report.md, metrics.json and pr.png for one evaluation; returns the metrics."""
    s = ev.summary()
    params = memory.params
    write_csv(out / "ranking.csv", RANKING_HEADER, ev.ranking_rows(memory.key_names))
    write_csv(out / "per_query.csv", PER_QUERY_HEADER, _per_query_rows(ev, memory.key_names))
    winners = ev.winner_counts(len(memory.angles)).tolist()
    metrics = {"title": title, "descriptor": params.descriptor.value, "params": params.to_dict(),
               "n_keys": len(memory), "n_tests": s.n_tests, "correct_mu1": s.correct_mu1,
               "effectiveness_mu1_pct": s.eff_mu1, "correct_mu2": s.correct_mu2, "effectiveness_mu2_pct": s.eff_mu2,
               "recall_at_1": s.recall1, "recall_at_5": s.recall5, "average_precision": s.average_precision,
               "median_ms_per_query": s.median_ms, "pattern_angles": list(memory.angles),
               "top1_vocabulary_counts": winners}
    atomic_write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    table = format_paper_table([(params.descriptor.label, s)])
    extra = ""
    if len(memory.angles) > 1:
        extra = "\nTop-1 vocabulary (pattern angle: count): " + ", ".join(
            f"{a:+g} deg: {c}" for a, c in zip(memory.angles, winners)) + "\n"
    atomic_write_text(out / "report.md", f"# {title}\n\n{memory.describe()}\n\n{table}\n{extra}")
    plot_pr_curves(out / "pr.png", {params.descriptor.label: ev.pr()}, title)
    return metrics
