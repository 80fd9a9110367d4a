"""`vslam bench localize`: visual-memory localisation on real image sets, in the paper's table layout.

Sets (from ../shared/data): corridor (reference traverse = memory, second traverse = queries), corridor-rot (the
same queries rotated by 10-30 degrees, alternating sign, seeded), kitti (two KITTI snippets, every 3rd frame a key
image), pairs (the 48 labelled pairs: one key image per scene). Every descriptor runs on every set, beside the
`pydbow` package on the same images and the same (ORB / BRIEF) descriptors. Then: the BRIEFROT theta sweep (Fig. 11),
repeatability over vocabulary rebuilds (Table 8) and the query time against a 1000-image 640x480 memory.
Prints markdown tables, writes JSON and PNG plots into --out.

Each image's descriptors are extracted once per descriptor (and pattern angle) and reused by every stage; each
vocabulary is built once per (key images, parameters, seed) and reused (corridor and corridor-rot share their key
images, BRIEFROT's unrotated vocabulary is the BRIEF vocabulary of the same seed). The time per query is still
extraction + scoring: each query's extraction time is recorded when it is first extracted.
"""
from __future__ import annotations

import argparse
import datetime
import importlib.util
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from loops.vocab import DescriptorName, preset
from odometry.shared.atomic_io import atomic_path, atomic_write_text
from vslam.bench.localize_runs import Bench, shared_words
from vslam.bench.place_sets import SETS, PlaceSet, load_set, write_set_truth
from vslam.bench.results import BenchResult, write_json
from vslam.evaluation.place_recognition import format_paper_table, summary_dict
from vslam.evaluation.plots import plot_pr_curves, pyplot
from vslam.evaluation.tables import format_table
from vslam.paths import shared_data_dir

ALL_DESCRIPTORS = ("brief", "briefrot", "orb", "surf", "color-random", "color-whole", "color-half")
REPEAT_DESCRIPTORS = ("brief", "briefrot", "color-random", "orb", "surf")   # the rows of the paper's Table 8
REPEAT_SETS = ("corridor", "kitti", "pairs")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="smaller run (~ a few minutes): fewer queries, builds, angles")
    p.add_argument("--out", default="bench-out/localize", help="output folder for JSON, CSV truth files and plots")
    p.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS))
    p.add_argument("--descriptors", nargs="+", choices=ALL_DESCRIPTORS, default=list(ALL_DESCRIPTORS))
    p.add_argument("--preset", default="paper", help="vocabulary preset (paper: k=8, L=8 as in the paper; default; fast)")
    p.add_argument("--no-pydbow", action="store_true", help="skip the pydbow comparison")
    p.add_argument("--skip", nargs="*", default=[], choices=("sets", "sweep", "repeat", "timing"),
                   help="parts to skip")
    p.add_argument("--builds", type=int, help="vocabulary builds per descriptor for repeatability (default 30; "
                                              "quick 10; the paper used 100)")
    p.add_argument("--timing-images", type=int, help="memory size for the query-time target (default 1000)")
    p.add_argument("--repeat-study", action="store_true",
                   help="instead of the tables: repeatability and Recall@1 of BRIEF / BRIEFROT under vocabulary-build "
                        "options (Lloyd iterations, k-means++ restarts, more descriptors)")



# ---- tables and plots --------------------------------------------------------------------------------------------
def spread_table(report_sets: dict) -> str:
    names = list(report_sets)
    labels = []
    for v in report_sets.values():
        labels += [d for d in v["details"] if d not in labels and "z_other_keys" in v["details"][d]]
    rows = []
    for d in labels:
        cells = []
        for name in names:
            x = report_sets[name]["details"].get(d)
            cells.append(f"{x['z_other_keys']:.1f} / {100 * x['z_other_weight']:.0f} %" if x else "-")
        rows.append((d, *cells))
    return format_table(("Descriptor", *names), rows)


def plot_sweep(path: Path, rows, title: str) -> None:
    plt = pyplot()
    th = [r[0] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.2), dpi=100)
    ax.plot(th, [r[1].eff_mu1 for r in rows], "o-", label="mu1 = 1")
    ax.plot(th, [r[1].eff_mu2 for r in rows], "s--", label="mu2 < 2.5")
    ax.set_xlabel("BRIEFROT theta (deg; 0 = BRIEF)")
    ax.set_ylabel("effectiveness (%)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def repeat_table(values: dict) -> str:
    rows = []
    for set_name, rep in values.items():
        for name, v in rep.items():
            rows.append((set_name, DescriptorName(v["descriptor"]).label + (f" {v['variant']}" if v["variant"] else ""),
                         v["n_builds"], f"{100 * v['mu1']:.1f} ± {100 * v['mu1_se']:.1f}", round(100 * v["top1"], 1),
                         round(100 * v["mean_success"], 1))
                        + ((round(100 * v["recall1_mean"], 1), round(100 * v["recall1_sd"], 1),
                            round(100 * v["mu1_all_queries"], 1)) if "recall1_mean" in v else ()))
    headers = ("Set", "Descriptor", "builds", "Repeatability, mu1=1 outcome (%) ± se", "Repeatability, top-1 key (%)",
               "mean mu1=1 rate (%)")
    if rows and len(rows[0]) > len(headers):
        headers += ("Recall@1 mean over builds (%)", "Recall@1 sd (%)", "Repeatability, all queries (%)")
    return format_table(headers, rows)



# ---- stages ------------------------------------------------------------------------------------------------------
@dataclass
class _Run:
    """One run of the benchmark: its inputs, the sets loaded so far, the report and the markdown sections."""
    args: argparse.Namespace
    data: Path
    out: Path
    bench: Bench
    report: dict
    md: list[str] = field(default_factory=list)
    loaded: dict[str, PlaceSet] = field(default_factory=dict)

    def get_set(self, name: str) -> PlaceSet:
        if name not in self.loaded:
            self.loaded[name] = load_set(name, self.data, self.args.quick)
            write_set_truth(self.out / "truth" / f"{name}.csv", self.loaded[name])
        return self.loaded[name]

    def stage_done(self, name: str, t0: float) -> None:
        self.report["stage_seconds"][name] = time.perf_counter() - t0
        print(f"== {name} stage: {self.report['stage_seconds'][name] / 60:.1f} min", flush=True)


def _sets_stage(r: _Run) -> None:
    """Every descriptor on every set (the paper's Tables 2-7), then how mu2's weights spread."""
    t0 = time.perf_counter()
    for name in r.args.sets:
        ps = r.get_set(name)
        print(f"== {name}: {len(ps.keys)} key images, {len(ps.queries)} queries", flush=True)
        res = r.bench.run_set(ps, r.args.descriptors)
        table = format_paper_table(res.rows)
        # only colour vocabularies on grayscale sets are skipped: one line for them
        skipped = "".join(f"\n{', '.join(res.skipped)}: skipped ({why.replace(d, '/'.join(res.skipped))})"
                          for d, why in list(res.skipped.items())[:1])
        r.md.append(f"#### {name}\n\n{ps.note}.\n\n{table}\n{skipped}\n")
        plot_pr_curves(r.out / f"pr_{name}.png", res.curves, f"{name}: top-1 precision-recall")
        r.report["sets"][name] = {"note": ps.note, "n_keys": len(ps.keys), "n_queries": len(ps.queries),
                                  "rows": {label: summary_dict(s) for label, s in res.rows},
                                  "skipped": res.skipped, "details": res.extra}
    r.md.append("#### mu2's weights: other key images with z > 0 per key / their share of the weights\n\n"
                "z_l(I*_k) = similarity of key l to the true key k in the memory (1 for k, 0 below "
                "min_shared words); a share of 0 % makes mu2 = mu1.\n\n" + spread_table(r.report["sets"]) + "\n")
    r.stage_done("sets", t0)


def _sweep_stage(r: _Run) -> None:
    """BRIEFROT effectiveness against its rotation angle theta on corridor-rot (Fig. 11)."""
    t0 = time.perf_counter()
    ps = r.get_set("corridor-rot")
    thetas = [0, 8, 16] if r.args.quick else [0, 4, 8, 12, 16, 20, 24]
    print("== BRIEFROT theta sweep on corridor-rot", flush=True)
    rows = r.bench.theta_sweep(ps, thetas)
    table = format_table(("theta (deg)", "Effectiveness mu1 (%)", "Effectiveness mu2 (%)", "Recall@1",
                          "Recall@5", "AP", "top-1 vocabulary 0/+theta/-theta"),
                         [(th, round(s.eff_mu1, 2), round(s.eff_mu2, 2), round(s.recall1, 3), round(s.recall5, 3),
                           round(s.average_precision, 3), "/".join(map(str, w))) for th, s, w in rows])
    r.md.append(f"#### BRIEFROT theta sweep (corridor-rot; theta 0 = BRIEF)\n\n{table}\n")
    plot_sweep(r.out / "theta_sweep.png", rows, "BRIEFROT on corridor queries rotated 10-30 deg")
    r.report["theta_sweep"] = [{"theta": th, **summary_dict(s), "top1_vocabulary_counts": w} for th, s, w in rows]
    r.stage_done("sweep", t0)


def _repeat_stage(r: _Run) -> None:
    """Repeatability over vocabulary rebuilds (Table 8) and the retrieval signal behind it."""
    t0 = time.perf_counter()
    n_builds = r.args.builds or (10 if r.args.quick else 30)
    print(f"== repeatability: {n_builds} vocabulary builds per descriptor", flush=True)
    rep_desc = [d for d in REPEAT_DESCRIPTORS if d in r.args.descriptors]
    rep = r.report["repeatability"] = {"n_builds": n_builds, "n_queries": 10, "values": {}}
    for set_name in REPEAT_SETS:
        ps = r.get_set(set_name)
        descs = [d for d in rep_desc if not (ps.grayscale and DescriptorName(d).is_color)]
        rep["values"][set_name] = r.bench.repeatability(ps, descs, n_builds)
        rep.setdefault("signal", {})[set_name] = shared_words(r.bench, ps)
    signal = "; ".join(f"{name} {v['best_true_key_words']:g} vs {v['best_wrong_key_words']:g} of "
                       f"{v['words_per_query']:g}" for name, v in rep["signal"].items())
    r.md.append(f"#### Repeatability of visual vocabularies (Table 8): {n_builds} builds (seeds 0..{n_builds - 1}), "
                f"10 queries per set\n\n{repeat_table(rep['values'])}\n\n"
                f"Retrieval signal (BRIEF, seed 0; median over the queries of the words shared with the best true "
                f"key vs the best wrong key, of the query's descriptors): {signal}.\n")
    r.stage_done("repeatability", t0)


def _timing_stage(r: _Run) -> None:
    """Median query time against a large 640x480 memory, against pydbow's."""
    t0 = time.perf_counter()
    n_keys = r.args.timing_images or (300 if r.args.quick else 1000)
    print(f"== query time against a {n_keys}-image 640x480 memory", flush=True)
    tim_desc = [d for d in ("brief", "briefrot", "orb") if d in r.args.descriptors]
    tim = r.bench.timing(r.data, n_keys, 20 if r.args.quick else 40, tim_desc)
    rows = []
    ref = tim["rows"].get("pydbow-orb", {}).get("query_ms")
    for d, row in tim["rows"].items():
        speed = f"{ref / row['query_ms']:.1f}x" if ref else "-"
        rows.append((d, row["query_ms"], row.get("extract_ms", float("nan")), row.get("score_ms", float("nan")),
                     "/".join(map(str, row["words"])), round(row["vocabulary_build_s"], 1), speed))
    table = format_table(("Descriptor", "Median query (ms)", "extraction (ms)", "scoring (ms)", "words",
                          "vocabulary build (s)", "speed-up vs pydbow"), rows)
    r.md.append(f"#### Query time, {tim['n_keys']}-image memory at 640x480 (median over {tim['n_queries']} "
                f"queries x 3; pydbow x 1)\n\n{tim['note']}.\n\n{table}\n")
    r.report["timing"] = tim
    r.stage_done("timing", t0)


STAGES = (("sets", _sets_stage), ("sweep", _sweep_stage), ("repeat", _repeat_stage), ("timing", _timing_stage))


# ---- the benchmark -----------------------------------------------------------------------------------------------
def run_repeat_study(args, bench: Bench, data: Path, out: Path) -> BenchResult:
    """Gap study: do Lloyd iterations, k-means++ restarts or more descriptors make builds steadier?"""
    n_builds = args.builds or (10 if args.quick else 30)
    variants = {"baseline": {}, "iters=30": {"kmeans_iters": 30}, "restarts=3": {"kmeans_restarts": 3},
                "features=1000": {"n_features": 1000}, "train on 1500/img": {"train_features": 1500}}
    values = {}
    for set_name in ("corridor", "kitti"):
        ps = load_set(set_name, data, args.quick)
        print(f"== build-option study on {set_name}: {n_builds} builds per option", flush=True)
        values[set_name] = bench.repeatability(ps, [d for d in ("brief", "briefrot") if d in args.descriptors],
                                               n_builds, variants=variants, all_queries=True)
    table = repeat_table(values)
    text = (f"### Repeatability and Recall@1 under vocabulary-build options ({n_builds} builds each)\n\n"
            f"`{' '.join(['vslam'] + sys.argv[1:])}` ({datetime.date.today().isoformat()})\n\n{table}\n")
    print("\n" + text)
    write_json(out / "repeat_study.json", {"n_builds": n_builds, "variants": variants, "values": values})
    atomic_write_text(out / "repeat_study.md", text)
    return BenchResult()   # a study, not the documented tables: docs/benchmarks.md is left alone


def _pydbow_config(args: argparse.Namespace) -> tuple[dict | None, str]:
    """The pydbow comparison's settings, or None and why not."""
    if args.no_pydbow:
        return None, ""
    if importlib.util.find_spec("dbow") is None:   # the `pydbow` distribution installs the module `dbow`
        note = "pydbow is not installed (pip install -e '.[bench]'): comparison skipped"
        print(note)
        return None, note
    quick = args.quick
    return {"k": 10, "depth": 2 if quick else 3, "max_train": 3000 if quick else 5000,
            "features": ["orb"] if quick else ["orb", "brief"]}, ""


def run(args: argparse.Namespace) -> BenchResult:
    data = shared_data_dir(required=True)
    out = Path(args.out)
    base = preset(args.preset)
    pydbow_cfg, pydbow_note = _pydbow_config(args)
    bench = Bench(base, pydbow_cfg)
    if args.repeat_study:
        return run_repeat_study(args, bench, data, out)
    command = " ".join(["vslam"] + sys.argv[1:]) if Path(sys.argv[0]).name != "pytest" else "vslam bench localize"
    report: dict = {"quick": args.quick, "preset": base.to_dict(), "pydbow": pydbow_cfg, "pydbow_note": pydbow_note,
                    "command": command, "date": datetime.date.today().isoformat(), "sets": {}, "stage_seconds": {}}
    t_start = time.perf_counter()
    r = _Run(args, data, out, bench, report)
    for name, stage in STAGES:
        if name not in args.skip:
            stage(r)
    report["elapsed_s"] = time.perf_counter() - t_start
    head = (f"`{command}` on {report['date']}: {report['elapsed_s'] / 60:.1f} min ("
            + ", ".join(f"{k} {v / 60:.1f}" for k, v in report["stage_seconds"].items()) + " min)\n")
    text = head + "\n" + "\n".join(r.md)
    print("\n" + text)
    write_json(out / "localize.json", report)
    atomic_write_text(out / "localize.md", text)
    print(f"wrote {out / 'localize.json'}, {out / 'localize.md'} and plots in {out}")
    return BenchResult("\n".join(r.md))
