"""`python -m vslam.bench.loop_stages`: every verified candidate of a run lands in exactly one stage, and the
stages agree with what the run reports (accepted, kept)."""
from __future__ import annotations

from dataclasses import replace

from vslam.bench.loop_stages import GROUPS, STAGES, loop_stages, main
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.sim import SimConfig, simulate


def _config() -> PipelineConfig:
    cfg = PipelineConfig()
    return replace(cfg, recording=replace(cfg.recording, enabled=False))


def test_stages_account_for_every_candidate_and_match_the_run(tmp_path, capsys):
    simulate(SimConfig(length=4.0, fps=15.0, speed=0.5, seed=4, laps=2), tmp_path / "seq")
    seq = open_sequence(tmp_path / "seq")
    vo = Pipeline(_config()).odometry(seq)
    out = loop_stages(seq, _config(), odometry=vo)
    res = Pipeline(_config()).run(seq, odometry=vo)
    counts = out["counts"]
    assert sum(sum(c.values()) for c in counts.values()) == out["candidates"] == len(res.loops)
    assert all(s in STAGES for g in GROUPS for s in counts[g])
    kept = sum(counts[g].get("kept", 0) for g in GROUPS)
    rejected = sum(counts[g].get("rejected by back end", 0) for g in GROUPS)
    assert kept == sum(1 for lp in res.loops if lp.accepted and lp.inlier) and kept > 0
    assert kept + rejected == sum(1 for lp in res.loops if lp.accepted)
    assert counts["J = 0"].get("kept", 0) == 0          # a clean simulated floor: no loop between places apart
    assert out["queries_shortlisting_a_true_place"] > 0 and out["positive_queries"] > 0
    assert main([str(tmp_path / "seq"), "--mode", "4"]) == 0
    assert "verified candidates" in capsys.readouterr().out
