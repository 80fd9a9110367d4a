"""The measurements of `vslam bench localize`: every descriptor on a place set (the paper's tables), the BRIEFROT
theta sweep (Fig. 11), repeatability over vocabulary rebuilds (Table 8) and the query time against a large memory;
each image's features and each vocabulary computed once (see `vslam.bench.vocab_cache`)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loops.vocab import (
    DescriptorName,
    GrayscaleImageError,
    VisualMemory,
    brief_angles,
    evaluate_descriptors,
    extract,
    repeatability,
)
from vslam.bench.place_sets import PlaceSet, timing_images
from vslam.bench.pydbow_memory import PydbowMemory
from vslam.bench.timing import median
from vslam.bench.vocab_cache import Features, Vocabularies


@dataclass
class SetResult:
    rows: list = field(default_factory=list)       # (label, Summary)
    curves: dict = field(default_factory=dict)     # label -> PRCurve
    skipped: dict = field(default_factory=dict)    # descriptor -> reason
    extra: dict = field(default_factory=dict)


@dataclass
class Bench:
    base: object
    pydbow_cfg: dict | None
    features: Features = field(default_factory=Features)
    vocabs: Vocabularies = field(default_factory=Vocabularies)
    pydbow: dict = field(default_factory=dict)

    def params(self, ps: PlaceSet, desc: str, **changes):
        return self.base.replace(descriptor=desc, min_image_side=ps.min_side, **changes)

    def memory(self, ps: PlaceSet, params):
        angles = brief_angles(params)
        per_angle = self.features.keys(ps, params, angles)
        return self.vocabs.memory(ps.keys_id, ps.key_names, params, per_angle, angles)

    def run_set(self, ps: PlaceSet, descriptors) -> SetResult:
        res = SetResult()
        for desc in descriptors:
            params = self.params(ps, desc)
            try:
                memory, build_s = self.memory(ps, params)
            except GrayscaleImageError as exc:
                res.skipped[desc] = str(exc)
                continue
            ev = evaluate_descriptors(memory, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            res.rows.append((params.descriptor.label, s))
            res.curves[params.descriptor.label] = ev.pr()
            res.extra[desc] = {"vocabulary_build_s": build_s, "words": [t.n_words for t in memory.trees],
                               "top1_vocabulary_counts": ev.winner_counts(len(memory.angles)).tolist(),
                               "pattern_angles": list(memory.angles), **key_similarity_spread(memory)}
            print(f"  [{ps.name}] {params.descriptor.label}: R@1 {s.recall1:.3f}, mu1=1 {s.eff_mu1:.1f} %, "
                  f"mu2<2.5 {s.eff_mu2:.1f} %, {s.median_ms:.1f} ms/query, vocabulary {build_s:.1f} s", flush=True)
        for feat in (self.pydbow_cfg or {}).get("features", []):
            params = self.params(ps, feat)
            key = (ps.keys_id, feat)
            if key not in self.pydbow:
                cfg = self.pydbow_cfg
                t0 = time.perf_counter()
                pm = PydbowMemory(self.features.keys(ps, params, (0.0,))[0], ps.key_names, params, cfg["k"],
                                  cfg["depth"], cfg["max_train"])
                self.pydbow[key] = (pm, time.perf_counter() - t0)
            pm, build_s = self.pydbow[key]
            ev = evaluate_descriptors(pm, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            label = f"pydbow ({params.descriptor.label})"
            res.rows.append((label, s))
            res.curves[label] = ev.pr()
            res.extra[f"pydbow-{feat}"] = {"vocabulary_build_s": build_s, "words": [pm.n_words]}
            print(f"  [{ps.name}] {label}: R@1 {s.recall1:.3f}, {s.median_ms:.1f} ms/query, build {build_s:.1f} s",
                  flush=True)
        return res

    def theta_sweep(self, ps: PlaceSet, thetas) -> list[tuple]:
        """Fig. 11: BRIEFROT effectiveness against the rotation angle theta (theta = 0 degenerates to three copies of
        BRIEF, which is why the BRIEF row stands in for it)."""
        rows = []
        for th in thetas:
            params = self.params(ps, "brief" if th == 0 else "briefrot", rot_theta_deg=float(th))
            memory, _ = self.memory(ps, params)
            ev = evaluate_descriptors(memory, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            rows.append((float(th), s, ev.winner_counts(len(memory.angles)).tolist()))
            print(f"  [theta sweep] theta {th:g}: R@1 {s.recall1:.3f} mu1=1 {s.eff_mu1:.1f} % "
                  f"mu2<2.5 {s.eff_mu2:.1f} %", flush=True)
        return rows

    def repeatability(self, ps: PlaceSet, descriptors, n_builds: int, n_queries: int = 10,
                      variants: dict | None = None, all_queries: bool = False) -> dict:
        """Table 8: rebuild each vocabulary with seeds 0..n_builds-1 (Color-Random also redraws its patches) and
        query n_queries fixed, evenly spaced queries. Per query, the share of builds giving its most frequent
        output, averaged over the queries; the output read as the mu1 = 1 outcome (the paper's "highest frequency
        output considering mu1 = 1") and, stricter, as the identity of the top-1 key image. `variants` maps a label
        to parameter changes (the build-option study); `all_queries` also scores every query for Recall@1.
        Builds run seed by seed, so BRIEFROT's unrotated vocabulary is the BRIEF one of the same seed; no tree is
        kept beyond its seed."""
        pick = np.linspace(0, len(ps.queries) - 1, n_queries).round().astype(int)
        score_idx = np.arange(len(ps.queries)) if all_queries else pick
        truth = [set(ps.truth[ps.queries[i][0]]) for i in range(len(ps.queries))]
        runs = [(desc, label, dict(changes)) for desc in descriptors for label, changes in
                (variants or {"": {}}).items()]
        top1 = {(d, lab): np.full((n_builds, len(score_idx)), -1) for d, lab, _ in runs}
        seconds = {(d, lab): 0.0 for d, lab, _ in runs}
        for r in range(n_builds):
            trees: dict = {}   # this seed's vocabularies, shared between BRIEF and BRIEFROT
            for desc, label, changes in runs:
                t0 = time.perf_counter()
                top1[desc, label][r] = self._seed_top1(ps, desc, changes, r, trees, score_idx)
                seconds[desc, label] += time.perf_counter() - t0
        out = {}
        for desc, label, _ in runs:
            name = desc + (f" {label}" if label else "")
            out[name] = {"descriptor": desc, "variant": label, "n_builds": n_builds,
                         **_repeatability_stats(top1[desc, label], truth, score_idx, pick, all_queries),
                         "seconds": seconds[desc, label]}
            print(f"  [repeatability] [{ps.name}] {name}: mu1=1 outcome {100 * out[name]['mu1']:.1f} % "
                  f"(se {100 * out[name]['mu1_se']:.1f}), top-1 key {100 * out[name]['top1']:.1f} % over "
                  f"{n_builds} builds" + (f", R@1 {100 * out[name]['recall1_mean']:.1f} %" if all_queries else "")
                  + f" ({out[name]['seconds']:.0f} s)", flush=True)
        return out

    def _seed_top1(self, ps: PlaceSet, desc: str, changes: dict, seed: int, trees: dict, score_idx) -> np.ndarray:
        """Top-1 key of each scored query with the vocabularies of one seed (built into `trees` when missing)."""
        train_features = changes.get("train_features")
        params = self.params(ps, desc, seed=seed, **{k: v for k, v in changes.items() if k != "train_features"})
        redraw = params.descriptor is DescriptorName.COLOR_RANDOM   # its patches depend on the seed
        angles = brief_angles(params)
        per_angle = self.features.keys(ps, params, angles, cache=not redraw)
        tp = params.replace(n_features=train_features) if train_features else params
        train = self.features.keys(ps, tp, angles) if train_features else per_angle
        built = []
        for o, a in enumerate(angles):
            key = self.vocabs.key(ps.keys_id, tp, o, a)
            if key not in trees:
                trees[key] = self.vocabs.tree(ps.keys_id, tp, o, a, train[o], cache=False)[0]
            built.append(trees[key])
        memory = VisualMemory.from_trees(built, per_angle, ps.key_names, params, angles)
        top1 = np.full(len(score_idx), -1)
        for j, (_, d, _) in enumerate(self.features.queries(ps, params, score_idx, cache=not redraw)):
            if d is not None:
                rk = memory.query_descriptors(d)
                top1[j] = rk.keys[0] if len(rk) else -1
        return top1

    def timing(self, data: Path, n_keys: int, n_queries: int, descriptors, repeats: int = 3) -> dict:
        """Median query time (extraction + scoring) against an n_keys memory. All memories are built first, then
        timed round-robin (every query through every method in turn), so load from other processes hits them
        alike."""
        keys, queries, note = timing_images(data, n_keys, n_queries)
        ps = PlaceSet("timing", note, [(f"k{i:04d}", k) for i, k in enumerate(keys)], [], {}, f"timing/{n_keys}",
                      "timing/queries")
        out = {"note": note, "n_keys": len(keys), "n_queries": len(queries), "rows": {}}
        memories = {}
        for desc in descriptors:
            params = self.base.replace(descriptor=desc)
            t0 = time.perf_counter()
            per_angle = self.features.keys(ps, params, brief_angles(params))
            extract_s = time.perf_counter() - t0
            memories[desc], build_s = self.vocabs.memory(ps.keys_id, ps.key_names, params, per_angle,
                                                         brief_angles(params))
            out["rows"][desc] = {"vocabulary_build_s": build_s, "words": [t.n_words for t in memories[desc].trees]}
            print(f"  [timing] {desc} memory: vocabulary {build_s:.0f} s (key extraction {extract_s:.0f} s)",
                  flush=True)
        if self.pydbow_cfg:
            params = self.base.replace(descriptor="orb")
            distinct = max(1, n_keys // 4)
            t0 = time.perf_counter()
            descs = self.features.keys(ps, params, (0.0,))[0][:distinct]
            memories["pydbow-orb"] = PydbowMemory(descs, ps.key_names[:distinct], params, self.pydbow_cfg["k"],
                                                  self.pydbow_cfg["depth"], self.pydbow_cfg["max_train"],
                                                  replicate=-(-n_keys // distinct))
            out["rows"]["pydbow-orb"] = {"vocabulary_build_s": time.perf_counter() - t0,
                                         "words": [memories["pydbow-orb"].n_words],
                                         "entries": len(memories["pydbow-orb"])}
            print(f"  [timing] pydbow memory ({len(memories['pydbow-orb'])} entries from {distinct} distinct key "
                  f"images): {out['rows']['pydbow-orb']['vocabulary_build_s']:.0f} s", flush=True)
        times = {name: {"total": [], "extract": [], "score": []} for name in memories}
        for rep in range(repeats):
            for q in queries:
                for name, memory in memories.items():
                    if name.startswith("pydbow") and rep > 0:
                        continue  # one pass is plenty at its speed
                    t0 = time.perf_counter()
                    d = extract(q, memory.params)[0]
                    t1 = time.perf_counter()
                    memory.query_descriptors(d)
                    t2 = time.perf_counter()
                    times[name]["extract"].append(t1 - t0)
                    times[name]["score"].append(t2 - t1)
                    times[name]["total"].append(t2 - t0)
        for name, t in times.items():
            out["rows"][name].update({"query_ms": 1e3 * median(t["total"]), "extract_ms": 1e3 * median(t["extract"]),
                                      "score_ms": 1e3 * median(t["score"])})
            print(f"  [timing] {name}: {out['rows'][name]['query_ms']:.1f} ms/query (extract "
                  f"{out['rows'][name]['extract_ms']:.1f}, score {out['rows'][name]['score_ms']:.2f})", flush=True)
        return out


def _repeatability_stats(t: np.ndarray, truth: list[set], score_idx, pick, all_queries: bool) -> dict:
    """Repeatability of the mu1 = 1 outcome (with a bootstrap standard error) and of the top-1 key over the
    builds (rows of `t`, top-1 key per scored query), on the `pick`ed queries; Recall@1 over all when asked."""
    n_builds = len(t)
    cols = np.searchsorted(score_idx, pick)
    success = np.array([[int(k) in truth[i] for k, i in zip(row, score_idx)] for row in t])
    s10, t10 = success[:, cols].astype(int), t[:, cols]
    rng = np.random.default_rng(0)
    boot = [repeatability(s10[rng.integers(0, n_builds, n_builds)]) for _ in range(200)]
    out = {"mu1": repeatability(s10), "mu1_se": float(np.std(boot)), "top1": repeatability(t10),
           "mean_success": float(s10.mean()), "per_query_success": s10.mean(0).tolist()}
    if all_queries:
        r1 = success.mean(1)
        out.update({"recall1_mean": float(r1.mean()), "recall1_sd": float(r1.std()),
                    "mu1_all_queries": repeatability(success.astype(int))})
    return out


def key_similarity_spread(memory) -> dict:
    """How mu2's weights z_l(I*_k) spread over the other key images: per key image, how many others have z > 0
    and which share of the weight sum_l z_l they get (0 = mu2 is mu1)."""
    n = len(memory)
    z = np.array([memory.key_similarity(k) for k in range(n)])
    others = z - np.diag(np.diag(z))
    return {"z_other_keys": float((others > 0).sum(1).mean()),
            "z_other_weight": float((others.sum(1) / z.sum(1)).mean())}



def shared_words(bench: "Bench", ps: PlaceSet, desc: str = "brief") -> dict:
    """How strong the retrieval signal is: per query, the words shared with its best-scoring true key image and
    with the best-scoring wrong one (single-vocabulary descriptor, seed 0); medians over the queries."""
    params = bench.params(ps, desc)
    memory, _ = bench.memory(ps, params)
    db, tree = memory.databases[0], memory.trees[0]
    true_w, wrong_w = [], []
    for name, d, _ in bench.features.queries(ps, params):
        if d is None:
            continue
        s = db.score(tree.transform(d), 1)
        is_true = np.isin(s.keys, ps.truth[name])
        true_w.append(int(s.shared[is_true][0]) if is_true.any() else 0)
        wrong_w.append(int(s.shared[~is_true][0]) if (~is_true).any() else 0)
    return {"descriptor": desc, "best_true_key_words": float(np.median(true_w)),
            "best_wrong_key_words": float(np.median(wrong_w)),
            "words_per_query": float(np.median([len(d) for _, d, _ in bench.features.queries(ps, params)
                                                if d is not None]))}
