"""The tables of `vslam bench graph`: per graph and outlier policy, one row per false-loop fraction, one column per
method (ATE m / true loops kept % / false loops rejected % / seconds), and a line per graph against issue 14's
targets.

Seeds are aggregated per (graph, policy, fraction, method): worst ATE (max), worst kept and rejected (min), median
seconds. Targets of the robust method ("ours"):
- clean graph: >= 99 % of true loops kept and ATE <= 1.01 x the converged reference's ATE + 0.1 mm (solver
  tolerance where the reference is the optimum itself, whose ATE is then 0);
- 10-50 % false loops: ATE <= 1.05 x ours' clean ATE + 1 cm, >= 99 % of false loops rejected, and at least as good
  as every robust peer in the table (GTSAM GNC, DCS, g2o DCS) on that row: ATE <= the peer's x (1 + PEER_SLACK_REL)
  + PEER_SLACK_M and false rejected >= the peer's;
- 70 / 80 %: reported, no target (the issue's stretch rows).
"""
from __future__ import annotations

import numpy as np

from vslam.bench.graph_data import TUNING_GRAPHS
from vslam.evaluation.tables import format_table

# "as good as a peer": ATE within 1 % + 1 mm of the peer's (the size of solver-tolerance differences between two
# optimisers ending at the same optimum, e.g. ring 1.432 vs 1.433 m), not a better or worse map
PEER_SLACK_REL = 0.01
PEER_SLACK_M = 0.001
COLUMNS = (("ours", "ours"), ("ours-isam2", "ours (iSAM2)"), ("ours-own-off", "ours, own_cycle_test off"),
           ("gtsam-gnc", "GTSAM GNC"), ("dcs", "DCS (GTSAM)"),
           ("g2o-dcs", "DCS (g2o)"), ("plain-lm", "plain LM"))
ROBUST_PEERS = ("gtsam-gnc", "dcs", "g2o-dcs")
STRETCH = 0.6              # fractions above this are stretch rows


def _bad(r: dict) -> str:
    return f"not finished in {r['timeout_s']:.0f} s" if r["status"] == "timeout" else r["status"]


def aggregate(rows: list[dict], version: str | None = None) -> dict[tuple, dict]:
    """(graph, policy, fraction, method) -> worst over seeds; crashed / failed rows counted, not averaged."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["graph"], r["policy"], round(float(r["fraction"]), 6), r["method"]), []).append(r)
    out = {}
    for k, rs in groups.items():
        ok = [r for r in rs if r.get("status", "ok") == "ok"]
        a = {"seeds": sorted(int(r["seed"]) for r in rs), "n_ok": len(ok), "n": len(rs),
             "bad": sorted({_bad(r) for r in rs if r.get("status", "ok") != "ok"}),
             "tuning": any(r.get("tuning") for r in rs),
             "stale": version is not None and any(r.get("version") not in (None, version) for r in rs)}
        if ok:
            a.update(ate=max(r["ate"] for r in ok), true_kept=min(r["true_kept"] for r in ok),
                     false_rejected=min(r["false_rejected"] for r in ok), s=float(np.median([r["s"] for r in ok])),
                     # rows before graph.labels: every injected loop counted wrong
                     wrong_rejected=min(r.get("wrong_rejected", r["false_rejected"]) for r in ok))
        out[k] = a
    return out


def _fmt_s(x: float) -> str:
    return f"{x:.2f}" if x < 10 else f"{x:.0f}"


def cell(a: dict | None, fraction: float) -> str:
    if a is None:
        return "–"
    if not a["n_ok"]:
        return " / ".join(a["bad"])
    rej = f"{100 * a['false_rejected']:.1f}" if fraction > 0 else "–"
    if fraction > 0 and a.get("wrong_rejected", a["false_rejected"]) != a["false_rejected"]:
        rej += f" ({100 * a['wrong_rejected']:.1f} of wrong)"
    text = f"{a['ate']:.4g} / {100 * a['true_kept']:.1f} / {rej} / {_fmt_s(a['s'])}"
    if a["n_ok"] < a["n"]:
        text += f" ({a['n'] - a['n_ok']} {'/'.join(a['bad'])})"
    return text + (" (stale)" if a["stale"] else "")


def misses(agg: dict, g: str, policy: str, f: float, head: dict, clean: float | None) -> list[str]:
    """Why ours misses the targets on one aggregated row (empty: met; None-like rows without ours are skipped)."""
    a = agg.get((g, policy, round(f, 6), "ours"))
    if a is None or not a["n_ok"]:
        return [] if a is None else [f"ours {'/'.join(a['bad'])}"]
    out = []
    if f == 0:
        lim = 1.01 * head["ref_ate"] + 1e-4
        if a["ate"] > lim:
            out.append(f"ATE {a['ate']:.4g} > {lim:.4g} m (+{100 * (a['ate'] - lim):.1f} cm)")
        if a["true_kept"] < 0.99:
            out.append(f"true kept {100 * a['true_kept']:.1f} % < 99 %")
        return out
    base = clean if clean is not None else head["ref_ate"]
    lim = 1.05 * base + 0.01
    if a["ate"] > lim:
        out.append(f"ATE {a['ate']:.4g} > {lim:.4g} m (+{100 * (a['ate'] - lim):.1f} cm)")
    if a["wrong_rejected"] < 0.99:
        out.append(f"wrong loops rejected {100 * a['wrong_rejected']:.1f} % < 99 %")
    for m in ROBUST_PEERS:
        p = agg.get((g, policy, round(f, 6), m))
        if p is None or not p["n_ok"]:
            continue
        if a["ate"] > p["ate"] * (1 + PEER_SLACK_REL) + PEER_SLACK_M:
            out.append(f"ATE {a['ate']:.4g} > {dict(COLUMNS)[m]} {p['ate']:.4g} m")
        if a["wrong_rejected"] < p["wrong_rejected"]:
            out.append(f"wrong loops rejected {100 * a['wrong_rejected']:.1f} < {dict(COLUMNS)[m]} "
                       f"{100 * p['wrong_rejected']:.1f} %")
    return out


def graph_section(g: str, head: dict, rows: list[dict], version: str | None) -> str:
    # files written before the converged reference: their clean reference is default plain LM
    head = {"ref_ate": head["clean_ate"], "ref_iterations": "?", "ref_s": head.get("clean_s", float("nan")),
            "clean_ate_opt": float("nan"), **head}
    agg = aggregate([r for r in rows if r["graph"] == g], version)
    methods = [m for m, _ in COLUMNS if any(k[3] == m for k in agg)]
    fractions = sorted({k[2] for k in agg})
    policies = [p for p in ("random", "local", "random-grouped", "local-grouped") if any(k[1] == p for k in agg)] \
        or ["clean graph only"]
    clean_ours = agg.get((g, "-", 0.0, "ours"))
    clean = clean_ours["ate"] if clean_ours and clean_ours["n_ok"] else None
    tuning = " (tuning graph)" if g in TUNING_GRAPHS else ""
    ref_s = _fmt_s(head["ref_s"]) if isinstance(head["ref_s"], float) and head["ref_s"] == head["ref_s"] else "?"
    lines = [f"#### {g}{tuning}: {head['nodes']} nodes, {head['loops']} loops, {head['dim']}D; ATE against "
             f"{head['reference']}",
             f"Converged reference (plain LM, tolerance 1e-12, {head['ref_iterations']} iterations, "
             f"{ref_s} s): ATE {head['ref_ate']:.4g} m. Plain LM at default tolerances: ATE "
             f"{head['clean_ate']:.4g} m, {100 * head['clean_ate_opt']:.2f} cm from the converged optimum."
             + (f" {head['note']}." if head.get("note") else "")]
    missed = []
    for policy in policies:
        body = []
        for f in fractions:
            p = "-" if f == 0 else policy
            if not any(k[0] == g and k[1] == p and k[2] == f for k in agg):
                continue
            why = [] if f > STRETCH else misses(agg, g, p, f, head, clean)
            target = "stretch" if f > STRETCH else ("yes" if not why else "**no**")
            if why and (f > 0 or policy == policies[0]):
                missed.append(f"{policy if f else 'clean'} {int(round(100 * f))} %: " + "; ".join(why))
            body.append([f"{int(round(100 * f))}"] + [cell(agg.get((g, p, f, m)), f) for m in methods] + [target])
        if body:
            lines.append(f"{policy} (cells: ATE m / true kept % / false rejected % / s)\n\n"
                         + format_table(["false %"] + [dict(COLUMNS)[m] for m in methods] + ["ours meets target"],
                                        body))
    lines.append("**" + g + "**: " + ("every row met the targets." if not missed else
                                     f"{len(missed)} row(s) miss: " + " | ".join(missed)))
    return "\n\n".join(lines)


def tables(heads: dict[str, dict], rows: list[dict], version: str | None = None) -> str:
    order = [g for g in heads if any(r["graph"] == g for r in rows)]
    return "\n\n".join(graph_section(g, heads[g], rows, version) for g in order)
