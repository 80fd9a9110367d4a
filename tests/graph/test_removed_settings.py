"""Settings of consensus-mode mechanisms that were off by default and measured not worth turning on were removed
(docs/graph.md keeps each measurement): a config file, `--set` or `replace` naming one is a ConfigError that names
the key and says it was removed and why, not an unknown key; two settings of the re-admission's iSAM2 steps were
renamed and name their new key."""
import dataclasses

import pytest

from graph.params import GraphParams, RobustParams
from odometry.shared.config import ConfigError
from vslam.pipeline.config import PipelineConfig

REMOVED = ("support_propagate", "reach_tail", "data_snooping", "snooping_min_redundancy", "snooping_max_loops",
           "trial_map_covariance", "group_disputed", "group_skip_majority", "cluster_weights", "kernel_start_always",
           "consensus_isam2_steps", "consensus_isam2_updates")


def test_every_removed_key_is_gone_and_explained():
    fields = {f.name for f in dataclasses.fields(RobustParams)}
    assert set(RobustParams.REMOVED) == set(REMOVED)
    assert not fields & set(REMOVED)
    for key, why in RobustParams.REMOVED.items():
        assert "docs/graph.md" in why, key


def test_config_file_naming_a_removed_key_is_a_config_error(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text("graph:\n  robust:\n    data_snooping: true\n")
    with pytest.raises(ConfigError) as exc:
        PipelineConfig.load(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: graph.robust.data_snooping: this setting was removed (off by default, measured "
                          "worse")
    assert msg.endswith("see docs/graph.md)")


@pytest.mark.parametrize("key", REMOVED)
def test_set_naming_a_removed_key_is_a_config_error(key):
    with pytest.raises(ConfigError, match=rf"^--set: graph\.robust\.{key}: this setting was removed \("):
        PipelineConfig().with_overrides([f"graph.robust.{key}=true"])


def test_replace_and_flat_keys_naming_a_removed_key_are_config_errors():
    with pytest.raises(ConfigError, match=r"robust\.reach_tail: this setting was removed \(off by default"):
        GraphParams().replace(robust={"reach_tail": True})
    with pytest.raises(ConfigError, match=r"^GraphParams: cluster_weights: this setting was removed"):
        GraphParams().replace(cluster_weights=True)


def test_renamed_isam2_step_settings_name_their_new_key():
    with pytest.raises(ConfigError, match=r"^--set: graph\.robust\.consensus_isam2_relinearize: this setting moved "
                                          r"to graph\.robust\.readmit_isam2_relinearize$"):
        PipelineConfig().with_overrides(["graph.robust.consensus_isam2_relinearize=0.02"])
    p = GraphParams().replace(robust={"readmit_isam2_max_changed": 20})
    assert p.robust.readmit_isam2_max_changed == 20
