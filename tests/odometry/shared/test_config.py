"""One configuration mechanism (odometry.shared.config): types, ranges, unknown keys, files, presets, overrides."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import pytest

from graph.params import GraphParams, IncrementalParams, RobustMode, RobustParams, SolverParams
from loops.cdvs.database import DatabaseParams
from loops.cdvs.params import CdvsParams, ExtractionParams, MatchParams, ModeParams
from loops.horizon.params import HorizonParams
from loops.vocab.params import VocabParams
from odometry.fusion import FusionConfig
from odometry.shared.config import Config, ConfigError, Interval, setting
from odometry.vo import VOConfig
from vslam.pipeline.config import KeyframePolicy, LoopConfig, PipelineConfig, RecordingConfig
from vslam.sim.floor import FloorParams
from vslam.sim.render import Effects
from vslam.sim.sensors import SensorNoise
from vslam.sim.simulate import SimConfig

ALL = [GraphParams, SolverParams, RobustParams, IncrementalParams, VocabParams, ExtractionParams, MatchParams,
       DatabaseParams, HorizonParams, VOConfig, FusionConfig, KeyframePolicy, LoopConfig, RecordingConfig,
       PipelineConfig, SimConfig, Effects, SensorNoise, FloorParams]


@dataclass(frozen=True)
class Inner(Config):
    gain: float = setting(1.0, range="(0, inf)", unit="dB", doc="amplifier gain")
    limit: float = setting(math.inf, range="[0, inf]")


@dataclass(frozen=True)
class Outer(Config):
    PRESETS = {"loud": {"inner": {"gain": 10.0}, "name": "loud"}}

    count: int = setting(3, range="[1, 6]")
    share: float = setting(0.5, range="[0, 1]")
    name: str = "quiet"
    kind: Literal["a", "b"] = "a"
    size: tuple[int, int] = setting((4, 3), range="[1, inf)")
    robust: RobustMode = RobustMode.GNC
    optional: float | None = setting(None, range="[0, inf)")
    inner: Inner = field(default_factory=Inner)

    def check(self) -> None:
        if self.size[0] < self.size[1]:
            raise ConfigError("size must be (wide, tall) with wide >= tall")


# ------------------------------------------------------------------ issue 15, item 9: values out of range
@pytest.mark.parametrize("text,message", [
    ("loops: {database: {shortlist: -5}}", "loops.database: shortlist must be >= 1, got -5"),
    ("loops: {database: {exclude_recent: -20}}", "loops.database: exclude_recent must be >= 0, got -20"),
    ("loops: {database: {confirmations: -3}}", "loops.database: confirmations must be >= 1, got -3"),
    ("loops: {pose_threshold_px: -3}", "loops: pose_threshold_px must be > 0, got -3.0"),
    ("graph: {robust: {gate_probability: 1.5}}", "graph.robust: gate_probability must be in (0, 1), got 1.5"),
    ("keyframes: {angle_deg: .nan}", "keyframes: angle_deg must be > 0, got nan"),
    ("vo: {max_features: 0}", "vo: max_features must be >= 1, got 0"),
    ("loops: {mode: 7}", "loops: mode must be one of 1, 2, 3, 4, 5, 6, got 7"),
    ("loops: {database: {min_overlap: 1.5}}", "loops.database: min_overlap must be in [0, 1], got 1.5"),
    ("recording: {jpeg_quality: 101}", "recording: jpeg_quality must be in [0, 100], got 101"),
    ("optimize_every: -1", "optimize_every must be >= 0, got -1"),
    ("fusion: {max_gap: .inf}", "fusion: max_gap must be > 0, got inf"),
])
def test_out_of_range_values_name_the_file_and_the_key(tmp_path, text, message):
    path = tmp_path / "config.yaml"
    path.write_text(text + "\n")
    with pytest.raises(ConfigError) as exc:
        PipelineConfig.load(path)
    assert str(exc.value) == f"{path}: {message}"


def test_types_are_checked_with_the_dotted_key(tmp_path):
    cases = {
        "vo: {grid: [8]}": "vo.grid: expected 2 values, got 1",
        "vo: {grid: [8, x]}": "vo.grid[1]: expected an integer, got 'x'",
        "vo: {quality: fine}": "vo.quality: expected a number, got 'fine'",
        "vo: {refine_tilt: 1}": "vo.refine_tilt: expected true or false, got 1",
        "loops: {model: 3}": "loops.model: expected a string, got 3",
        "loops: {database: 5}": "loops.database: expected a mapping of DatabaseParams settings, got 5",
        "graph: {solver: {isam2_factorization: lu}}":
            "graph.solver: isam2_factorization must be one of cholesky, qr, got 'lu'",
        "graph: {robust: maybe}": "graph.robust.method: 'maybe' is not one of consensus, gnc, huber, cauchy, none",
        "keyframes: {max_frames: 2.5}": "keyframes.max_frames: expected an integer, got 2.5",
    }
    for text, message in cases.items():
        path = tmp_path / "c.yaml"
        path.write_text(text + "\n")
        with pytest.raises(ConfigError) as exc:
            PipelineConfig.load(path)
        assert str(exc.value) == f"{path}: {message}", text


def test_unknown_keys_are_errors_with_a_suggestion():
    with pytest.raises(ConfigError, match=r"PipelineConfig: loops.databse: unknown setting .*did you mean 'database'"):
        PipelineConfig.from_dict({"loops": {"databse": {}}})
    with pytest.raises(ConfigError, match=r"GraphParams: zzz: unknown .*known ones are incremental, robust, solver"):
        GraphParams.from_dict({"zzz": 1})
    with pytest.raises(ConfigError, match="unknown setting"):
        GraphParams().replace(gnc_mu=2.0)


def test_values_are_converted_as_when_loading():
    cfg = PipelineConfig.from_dict({"vo": {"grid": [4, 3], "quality": "1e-3"},
                                    "graph": {"solver": {"lm_max_iterations": 50.0}}})
    assert cfg.vo.grid == (4, 3) and cfg.vo.quality == 0.001 and type(cfg.graph.solver.lm_max_iterations) is int
    assert GraphParams(robust="huber").robust.method is RobustMode.HUBER           # construction converts too
    assert Outer(size=[5, 2]).size == (5, 2)
    assert Outer(inner={"gain": 2}).inner == Inner(gain=2.0)


# ------------------------------------------------------------------ construction, replace, presets
def test_construction_validates_ranges_and_cross_field_rules():
    with pytest.raises(ConfigError, match=r"^FusionConfig: gyro_sigma must be >= 0, got -1.0$"):
        FusionConfig(gyro_sigma=-1.0)
    with pytest.raises(ConfigError, match=r"^VOConfig: grid\[0\] must be >= 1, got 0$"):
        VOConfig(grid=(0, 6))
    with pytest.raises(ConfigError, match=r"^Outer: size must be \(wide, tall\)"):
        Outer(size=(2, 5))
    with pytest.raises(ConfigError, match=r"^Outer: inner: gain must be > 0, got 0.0$"):
        Outer(inner={"gain": 0})
    with pytest.raises(ConfigError, match="kind: 'c' is not one of a, b"):
        Outer(kind="c")
    with pytest.raises(ConfigError, match=r"^MatchParams: scale_range must be"):
        MatchParams(scale_range=(2.0, 1.0))
    with pytest.raises(ConfigError, match="desc_bits must be a multiple of 8"):
        ModeParams(4, 4096, desc_bits=90, max_local=300, global_clusters=20, coord_block=2)


def test_infinity_only_where_the_range_includes_it():
    assert Inner().limit == math.inf
    with pytest.raises(ConfigError, match=r"gain must be > 0, got inf"):
        Inner(gain=math.inf)
    with pytest.raises(ConfigError, match=r"limit must be in \[0, inf\], got nan"):
        Inner(limit=math.nan)
    with pytest.raises(ConfigError, match=r"min_global must be a finite number, got -inf"):
        DatabaseParams(min_global=-math.inf)


def test_replace_is_a_validated_copy_and_merges_nested_mappings():
    base = Outer(count=2)
    changed = base.replace(share=0.25, inner={"gain": 3.0})
    assert changed == Outer(count=2, share=0.25, inner=Inner(gain=3.0)) and base == Outer(count=2)
    with pytest.raises(ConfigError, match=r"^Outer: share must be in \[0, 1\], got 2.0$"):
        base.replace(share=2.0)
    floor = CdvsParams.floor(4)
    assert floor.mode.global_clusters == 128 and floor.matching.scale_range == (0.8, 1.25)
    assert floor.mode.desc_bits == CdvsParams.for_mode(4).mode.desc_bits


def test_presets():
    assert Outer.preset("loud") == Outer(name="loud", inner=Inner(gain=10.0))
    assert Outer.preset("loud", count=4).count == 4
    with pytest.raises(ConfigError, match="unknown Outer preset 'soft'; choose one of loud"):
        Outer.preset("soft")
    assert GraphParams.preset("least_squares").robust.method is RobustMode.NONE
    assert SensorNoise.preset("none") == SensorNoise(**{k: 0.0 for k in SensorNoise.__dataclass_fields__})
    assert not Effects.preset("none").motion_blur and Effects.preset("none").dropped_frames == 0.0


@pytest.mark.parametrize("cls", [c for c in ALL if c.PRESETS])
def test_every_preset_builds(cls):
    for name in cls.PRESETS:
        assert isinstance(cls.preset(name), cls)


# ------------------------------------------------------------------ overrides (--set)
def test_with_overrides_parses_dotted_yaml_scalars():
    cfg = PipelineConfig().with_overrides(["loops.mode=5", "graph.robust=huber", "vo.grid=[4, 3]", "incremental=true",
                                           "graph.solver.lm_relative_tol=1e-4", "loops.model=null",
                                           "loops.database.shortlist=8"])
    assert cfg.loops.mode == 5 and cfg.graph.robust.method is RobustMode.HUBER and cfg.vo.grid == (4, 3)
    assert cfg.incremental
    assert cfg.graph.solver.lm_relative_tol == 1e-4 and cfg.loops.model is None and cfg.loops.database.shortlist == 8
    assert cfg.loops.database.confirmations == PipelineConfig().loops.database.confirmations   # the rest is kept
    later = cfg.with_overrides(["loops.mode=2"])
    assert later.loops.mode == 2 and later.graph.robust.method is RobustMode.HUBER


@pytest.mark.parametrize("items,message", [
    (["loops.mode=9"], "--set: loops: mode must be one of 1, 2, 3, 4, 5, 6, got 9"),
    (["loops.mdoe=2"], "--set: loops.mdoe: unknown setting"),
    (["loops.mode"], "--set: expected KEY=VALUE"),
    (["loops..mode=2"], "--set: expected KEY=VALUE"),
    (["loops=3"], "--set: loops: expected a mapping of LoopConfig settings, got 3"),
    (["loops.mode=2", "loops.mode.x=1"], "--set: loops.mode is set both as a value and as a section"),
    (["vo.max_features=lots"], "--set: vo.max_features: expected an integer, got 'lots'"),
])
def test_with_overrides_errors(items, message):
    with pytest.raises(ConfigError) as exc:
        PipelineConfig().with_overrides(items)
    assert str(exc.value).startswith(message)


# ------------------------------------------------------------------ files
def test_load_yaml_toml_json_and_dump_round_trip(tmp_path):
    (tmp_path / "a.yaml").write_text("loops:\n  mode: 2\ngraph: {robust: cauchy}\n")
    (tmp_path / "a.toml").write_text("[loops]\nmode = 2\n[graph]\nrobust = \"cauchy\"\n")
    (tmp_path / "a.json").write_text('{"loops": {"mode": 2}, "graph": {"robust": "cauchy"}}')
    loaded = [PipelineConfig.load(tmp_path / f"a.{ext}") for ext in ("yaml", "toml", "json")]
    assert loaded[0] == loaded[1] == loaded[2] and loaded[0].loops.mode == 2
    (tmp_path / "empty.yaml").write_text("")
    assert PipelineConfig.load(tmp_path / "empty.yaml") == PipelineConfig()
    cfg = PipelineConfig().with_overrides(["vo.grid=[4, 3]", "loops.exclude_distance=null"])
    for name in ("out.yaml", "out.json"):
        cfg.dump(tmp_path / name)
        assert PipelineConfig.load(tmp_path / name) == cfg
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("out")) == ["out.json", "out.yaml"]
    with pytest.raises(ConfigError, match="write a config as"):
        cfg.dump(tmp_path / "out.toml")


def test_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="config file not found"):
        PipelineConfig.load(tmp_path / "missing.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="list.yaml: expected a mapping of settings at the top level"):
        PipelineConfig.load(tmp_path / "list.yaml")
    (tmp_path / "bad.toml").write_text("[loops\n")
    with pytest.raises(ConfigError, match="bad.toml: cannot parse"):
        PipelineConfig.load(tmp_path / "bad.toml")


@pytest.mark.parametrize("cls", ALL)
def test_defaults_are_valid_and_survive_a_round_trip(cls):
    obj = cls()
    assert cls.from_dict(obj.to_dict()) == obj
    assert cls.from_dict({}, base=obj) == obj


def test_required_fields_and_describe():
    with pytest.raises(ConfigError, match="ModeParams: budget: missing required setting"):
        ModeParams.from_dict({"mode": 1})
    text = Outer.describe()
    assert "inner.gain" in text and "(0, inf)" in text and "dB" in text and "amplifier gain" in text
    assert "loops.database.shortlist" in PipelineConfig.describe()


def test_intervals():
    assert str(Interval.parse("(0, 1]")) == "(0, 1]" and Interval.parse("(0, 1]").rule() == "in (0, 1]"
    assert Interval.parse((0, None)).rule() == ">= 0" and Interval.parse("(-inf, 5)").rule() == "< 5"
    assert 0 not in Interval.parse("(0, 1]") and 1 in Interval.parse("(0, 1]")
    assert math.inf in Interval.parse("[0, inf]") and math.inf not in Interval.parse("[0, inf)")
    with pytest.raises(ValueError, match="bad range"):
        Interval.parse("0..1")


# ------------------------------------------------------------------ nested groups: shorthand and moved keys
@dataclass(frozen=True)
class Stage(Config):
    SHORTHAND = "method"

    method: RobustMode = RobustMode.NONE
    width: float = setting(1.0, range="(0, inf)")


@dataclass(frozen=True)
class Stages(Config):
    MOVED = {"width": "stage.width"}

    stage: Stage = field(default_factory=Stage)
    other: Inner = field(default_factory=Inner)


def test_a_scalar_for_a_group_sets_its_method_and_keeps_the_rest():
    s = Stages(stage="huber")
    assert s.stage == Stage(method=RobustMode.HUBER)
    wide = s.replace(stage={"width": 3.0}).replace(stage="cauchy")
    assert wide.stage == Stage(method=RobustMode.CAUCHY, width=3.0)
    assert Stages().with_overrides(["stage.width=2"]).with_overrides(["stage=gnc"]).stage == Stage(RobustMode.GNC, 2.0)
    with pytest.raises(ConfigError, match=r"Stages: stage.method: 'tukey' is not one of"):
        Stages.from_dict({"stage": "tukey"})
    with pytest.raises(ConfigError, match="other: expected a mapping of Inner settings, got 5"):
        Stages.from_dict({"other": 5})                       # no SHORTHAND: a scalar is still an error


def test_a_moved_key_names_its_new_home(tmp_path):
    with pytest.raises(ConfigError, match=r"^Stages: width: this setting moved to stage.width$"):
        Stages.from_dict({"width": 2.0})
    path = tmp_path / "old.yaml"
    path.write_text("graph:\n  lm_max_iterations: 50\n")
    with pytest.raises(ConfigError) as exc:
        PipelineConfig.load(path)
    assert str(exc.value) == f"{path}: graph.lm_max_iterations: this setting moved to graph.solver.lm_max_iterations"
    with pytest.raises(ConfigError, match=r"^--set: graph.isam2_batch_nodes: this setting moved to "
                                          r"graph.incremental.batch_nodes$"):
        PipelineConfig().with_overrides(["graph.isam2_batch_nodes=5"])
    with pytest.raises(ConfigError, match=r"this setting moved to robust.gate_loops"):
        GraphParams().replace(gate_loops=False)


def test_a_removed_key_says_so_and_why():
    @dataclass(frozen=True)
    class Pruned(Config):
        REMOVED = {"old": "measured worse"}
        kept: int = 1

    with pytest.raises(ConfigError, match=r"^Pruned: old: this setting was removed \(measured worse\)$"):
        Pruned.from_dict({"old": 2})
    with pytest.raises(ConfigError, match=r"^Pruned: olde: unknown setting"):
        Pruned.from_dict({"olde": 2})
    assert Pruned.from_dict({"kept": 3}).kept == 3


def test_graph_params_groups_round_trip_and_describe(tmp_path):
    cfg = PipelineConfig().with_overrides(["graph.robust.huber_k=2", "graph.solver=isam2", "graph.robust.method=huber",
                                           "graph.incremental.batch_nodes=7"])
    g = cfg.graph
    assert (g.robust.method, g.robust.huber_k, g.solver.method.value, g.incremental.batch_nodes) == \
        (RobustMode.HUBER, 2.0, "isam2", 7)
    assert g.robust.inlier_probability == GraphParams().robust.inlier_probability      # the rest is kept
    cfg.dump(tmp_path / "c.yaml")
    assert PipelineConfig.load(tmp_path / "c.yaml") == cfg
    text = PipelineConfig.describe()
    assert "graph.robust.huber_k" in text and "graph.incremental.batch_nodes" in text and "graph.solver.init" in text
    for name in GraphParams.PRESETS:                         # every group of every preset is a valid group config
        p = GraphParams.preset(name)
        assert GraphParams.from_dict(p.to_dict()) == p
