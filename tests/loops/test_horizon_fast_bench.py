"""The packed-vs-ORB comparison of `vslam bench horizon` (vslam/bench/horizon_fast.py): several packed presets and
ORB in one run, the per-pair figures as defined, and the real-pairs tables written into their own docs section."""
from __future__ import annotations

import argparse

import numpy as np
import pytest

from loops.horizon import HorizonParams
from tests.loops.test_horizon_bands import scene
from vslam.bench.horizon import publish_sections
from vslam.bench.horizon_fast import ORB, PairSet, backends, compare, fast_name


def small_set() -> PairSet:
    """Five places seen twice (the second view turned by 6 px), each test view paired with its own place and with
    two others; even places are one half, odd places the other."""
    images, rows, pairs, labels, half = {}, {}, [], [], []
    for k in range(5):
        images[f"s{k}"], images[f"t{k}"] = scene(10 + k), scene(10 + k, shift=6.0)
        rows[f"s{k}"] = rows[f"t{k}"] = 60.0
    for k in range(5):
        for j in (k, (k + 1) % 5, (k + 2) % 5):
            pairs.append((f"s{j}", f"t{k}"))
            labels.append(j == k)
            half.append(k % 2)
    return PairSet(images, rows, pairs, np.array(labels), np.array(half))


def test_compare_puts_every_packed_preset_and_orb_in_one_table():
    presets = {"fast": HorizonParams.preset("fast"), "lone": HorizonParams.preset("lone")}
    text, res = compare(small_set(), presets, {"tuning": 0, "reporting": 1})
    names = [fast_name(p, n, b) for n, p in presets.items() for b in backends()]
    for half in ("tuning", "reporting"):
        for name in names:
            r = res[half][name]
            assert r["auc"] == 1.0                       # the same place, turned, beats two other places
            assert r["strict_us"] == pytest.approx(2 * r["extraction_us"] + r["matching_us"])
        assert res[half][ORB]["pairs"] == res[half][names[0]]["pairs"]
        assert set(res[half]["orb_over_packed"]) == {f"{n}, {b}" for n in presets for b in backends()}
        for n in presets:      # the compiled and the numpy path give the same scores, hence the same AUC
            assert len({res[half][fast_name(presets[n], n, b)]["auc"] for b in backends()}) == 1
    assert res["trivial_call_us"] > 0
    for name in (*names, ORB, "One trivial array call"):
        assert name in text


def test_the_real_pairs_tables_go_to_their_own_docs_section(tmp_path):
    docs = tmp_path / "benchmarks.md"
    docs.write_text("<!-- bench:horizon -->\nSIFT table\n<!-- /bench:horizon -->\n\n"
                    "<!-- bench:horizon-real -->\nold\n<!-- /bench:horizon-real -->\n")
    args = argparse.Namespace(docs=None, docs_file=str(docs), command_line=["bench", "horizon", "--real-only"])
    publish_sections(args, {"horizon-real": "| new | table |"})
    text = docs.read_text()
    assert "| new | table |" in text and "old" not in text
    assert "SIFT table" in text                          # the crop bank's section is left alone
    assert "vslam bench horizon --real-only" in text
    publish_sections(argparse.Namespace(docs=False, docs_file=str(docs), command_line=None), {"horizon-real": "newer"})
    assert "newer" not in docs.read_text()               # --no-docs writes nothing
