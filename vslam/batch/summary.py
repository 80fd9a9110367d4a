"""The fleet summary at the end of a batch: one row per sequence, written as OUT/summary.csv, OUT/summary.json and
OUT/summary.png (per-sequence ATE where ground truth exists, frames/s, loops kept, failures)."""
from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_path, atomic_write_text
from vslam.evaluation.plots import pyplot
from vslam.evaluation.tables import format_table

COLUMNS = ("name", "status", "reused", "attempts", "frames", "seconds", "cpu_seconds", "frames_per_second", "ate_slam_m",
           "ate_slam_percent", "ate_vo_m", "loops_kept", "error", "sequence")


@dataclass
class BatchSummary:
    """Rows (dicts with COLUMNS) in input order, and where the summary files are."""
    rows: list[dict]
    out: Path
    wall_seconds: float = 0.0
    files: dict[str, Path] = field(default_factory=dict)

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] != "done"]

    @property
    def ok(self) -> bool:
        return not self.failed

    @property
    def exit_code(self) -> int:
        """0 when every sequence is done, 1 when any failed."""
        return 0 if self.ok else 1

    def counts(self) -> dict:
        done = [r for r in self.rows if r["status"] == "done"]
        return {"sequences": len(self.rows), "done": len(done), "failed": len(self.failed),
                "reused": sum(1 for r in done if r["reused"]), "ran": sum(1 for r in done if not r["reused"])}

    def format(self) -> str:
        """The table `vslam batch` prints."""
        def num(v, fmt):
            return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)

        table = format_table(
            ["sequence", "status", "frames", "frames/s", "ATE SLAM (m)", "loops kept", "attempts", "error"],
            [[r["name"], r["status"] + (" (earlier run)" if r["reused"] else ""), num(r["frames"], "d"),
              num(r["frames_per_second"], ".1f"), num(r["ate_slam_m"], ".4f"), num(r["loops_kept"], "d"),
              num(r["attempts"], "d"), (r["error"] or "")[:80]] for r in self.rows])
        c = self.counts()
        return (f"{table}\nvslam batch: {c['done']} of {c['sequences']} sequences done ({c['ran']} run now, "
                f"{c['reused']} from an earlier run), {c['failed']} failed, {self.wall_seconds:.1f} s")

    def write(self) -> dict[str, Path]:
        """summary.csv, summary.json and summary.png in the output folder."""
        self.out.mkdir(parents=True, exist_ok=True)
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in self.rows:
            w.writerow({k: "" if r.get(k) is None else r[k] for k in COLUMNS})
        self.files = {"csv": self.out / "summary.csv", "json": self.out / "summary.json",
                      "png": self.out / "summary.png"}
        atomic_write_text(self.files["csv"], buf.getvalue())
        atomic_write_text(self.files["json"], json.dumps({"counts": self.counts(), "wall_seconds": self.wall_seconds,
                                                          "sequences": self.rows}, indent=1, default=float) + "\n")
        plot_summary(self.files["png"], self.rows)
        return self.files


def _values(rows: list[dict], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else float(r[key]) for r in rows])


def plot_summary(path: Path, rows: list[dict]) -> None:
    """Three bar panels over the sequences (ATE of SLAM and VO, frames/s, loops kept); failed sequences are red
    bands with an x."""
    plt = pyplot()
    n = len(rows)
    fig, axes = plt.subplots(3, 1, figsize=(max(6.0, 0.45 * n + 2.5), 8), dpi=100, sharex=True)
    x = np.arange(n)
    failed = [i for i, r in enumerate(rows) if r["status"] != "done"]
    ate_slam, ate_vo = _values(rows, "ate_slam_m"), _values(rows, "ate_vo_m")
    axes[0].bar(x - 0.2, np.nan_to_num(ate_vo), 0.4, color="tab:orange", label="VO")
    axes[0].bar(x + 0.2, np.nan_to_num(ate_slam), 0.4, color="tab:blue", label="SLAM")
    axes[0].set_ylabel("ATE RMSE (m)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].bar(x, np.nan_to_num(_values(rows, "frames_per_second")), 0.6, color="tab:green")
    axes[1].set_ylabel("frames/s")
    axes[2].bar(x, np.nan_to_num(_values(rows, "loops_kept")), 0.6, color="tab:purple")
    axes[2].set_ylabel("loops kept")
    axes[2].yaxis.get_major_locator().set_params(integer=True)
    for ax in axes:
        ax.set_ylim(bottom=0)
        for i in failed:
            ax.axvspan(i - 0.45, i + 0.45, color="tab:red", alpha=0.25, lw=0)
        ax.grid(axis="y", alpha=0.3)
    for i in failed:
        axes[2].plot(i, 0, "x", color="tab:red", ms=10, mew=2)
    axes[2].set_xticks(x, [r["name"] for r in rows], rotation=60, ha="right", fontsize=8)
    done = n - len(failed)
    no_truth = any(r["status"] == "done" and r.get("ate_slam_m") is None for r in rows)
    axes[0].set_title(f"{n} sequences: {done} done, {len(failed)} failed (red)"
                      + ("\nATE only where ground truth exists" if no_truth else ""), fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
