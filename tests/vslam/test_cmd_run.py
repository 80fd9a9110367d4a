"""`vslam run --set KEY=VALUE`: dotted overrides of the pipeline config, validated like a config file."""
from __future__ import annotations

import yaml

from vslam.cli.main import main


def test_set_overrides_reach_the_effective_config(tmp_path, capsys):
    rc = main(["run", str(tmp_path / "seq"), "--out", str(tmp_path / "out"), "--set", "loops.recognizer=vocab",
               "--set", "vo.max_features=300", "--mode", "5", "--print-config"])
    assert rc == 0
    cfg = yaml.safe_load(capsys.readouterr().out)
    assert cfg["loops"]["recognizer"] == "vocab"
    assert cfg["loops"]["mode"] == 5
    assert cfg["vo"]["max_features"] == 300


def test_set_rejects_unknown_keys_and_out_of_range_values(tmp_path, capsys):
    base = ["run", str(tmp_path / "seq"), "--out", str(tmp_path / "out"), "--print-config"]
    assert main([*base, "--set", "loops.recogniser=vocab"]) == 2
    assert "loops.recogniser" in capsys.readouterr().err
    assert main([*base, "--set", "loops.database.shortlist=-5"]) == 2
    assert "shortlist" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
