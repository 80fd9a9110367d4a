"""Property tests of the sequence parsers and the config loader (issue 15): any mutation of a valid sequence
directory, camera.yaml, CSV stream, TUM file or config either loads or raises a typed error (ToolkitError) that
names the file; nothing else escapes. Fast in CI (few examples); `vslam bench fuzz` runs the long version."""
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from odometry.shared.errors import ToolkitError
from odometry.vo import VOConfig
from vslam.bench.fuzz import check_sequence
from vslam.bench.fuzz_cases import CAMERA_YAML, config_text, mutate_text, sequence_folder
from vslam.io import read_camera_yaml
from vslam.io.csvstreams import read_csv_columns
from vslam.io.sequence_dir import read_groundtruth
from vslam.pipeline import PipelineConfig

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
SEEDS = st.integers(0, 2**32 - 1)


def loads_or_names_the_file(fn, path):
    try:
        fn()
    except ToolkitError as exc:
        assert str(path) in str(exc), f"the error does not name {path}: {exc}"


@FAST
@given(seed=SEEDS)
def test_malformed_sequence_directories(tmp_path, seed):
    root = sequence_folder(random.Random(seed), tmp_path / f"s{seed}")
    loads_or_names_the_file(lambda: check_sequence(root), root)


@FAST
@given(seed=SEEDS)
def test_camera_yaml(tmp_path, seed):
    p = tmp_path / f"camera{seed}.yaml"
    rng = random.Random(seed)
    text = CAMERA_YAML
    for _ in range(rng.randint(1, 3)):
        text = mutate_text(rng, text)
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    loads_or_names_the_file(lambda: read_camera_yaml(p), p)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(max_size=120))
def test_camera_yaml_from_any_text(tmp_path, text):
    p = tmp_path / "camera.yaml"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    loads_or_names_the_file(lambda: read_camera_yaml(p), p)


CSV_SCHEMAS = {"frames.csv": (("timestamp", "image"), ("image",), "timestamp,image\n0.0,a.png\n0.1,b.png\n"),
               "odometry.csv": (("timestamp", "v", "omega"), (), "timestamp,v,omega\n0.0,0.1,0\n0.1,0.1,0.01\n"),
               "imu.csv": (("timestamp", "gyro_z"), (), "timestamp,gyro_z\n0.0,0.0\n0.05,0.01\n")}


@FAST
@given(seed=SEEDS, name=st.sampled_from(sorted(CSV_SCHEMAS)))
def test_csv_streams(tmp_path, seed, name):
    header, text_cols, valid = CSV_SCHEMAS[name]
    rng = random.Random(seed)
    text = valid
    for _ in range(rng.randint(1, 3)):
        text = mutate_text(rng, text)
    p = tmp_path / f"{seed}-{name}"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    loads_or_names_the_file(lambda: read_csv_columns(p, header, text_columns=text_cols), p)


@FAST
@given(seed=SEEDS)
def test_tum_groundtruth(tmp_path, seed):
    rng = random.Random(seed)
    text = "# t tx ty tz qx qy qz qw\n0.0 0 0 0 0 0 0 1\n0.1 0.01 0 0 0 0 0 1\n0.2 0.02 0 0 0 0 0 1\n"
    for _ in range(rng.randint(1, 3)):
        text = mutate_text(rng, text)
    p = tmp_path / f"gt{seed}.txt"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    loads_or_names_the_file(lambda: read_groundtruth(p), p)


@pytest.fixture(scope="module")
def valid_config():
    return PipelineConfig().dumps()


@FAST
@given(seed=SEEDS)
def test_pipeline_configs(tmp_path, valid_config, seed):
    p = tmp_path / f"c{seed}.yaml"
    p.write_text(config_text(random.Random(seed), valid_config), encoding="utf-8", errors="surrogatepass")

    def load():
        cfg = PipelineConfig.load(p)
        cfg.database_params()
    loads_or_names_the_file(load, p)


@FAST
@given(seed=SEEDS)
def test_vo_configs(tmp_path, seed):
    valid = "\n".join(f"{k}: {v}" for k, v in VOConfig().to_dict().items()
                      if isinstance(v, (int, float, bool, str))) + "\n"
    p = tmp_path / f"vo{seed}.yaml"
    p.write_text(config_text(random.Random(seed), valid), encoding="utf-8", errors="surrogatepass")
    loads_or_names_the_file(lambda: VOConfig.load(p), p)


# ---- cases the long fuzz found (each failed before its fix) -------------------------------------------------------
def test_info_on_a_single_pose_groundtruth(tmp_path):
    root = sequence_folder(random.Random(1), tmp_path / "s", corrupt=False)
    (root / "groundtruth.txt").write_text("0.0 0 0 0 0 0 0 1\n")
    check_sequence(root)   # before: TypeError formatting a None path length


def test_a_header_only_stream_is_ignored_with_a_warning_naming_it(tmp_path):
    root = sequence_folder(random.Random(2), tmp_path / "s", corrupt=False)
    (root / "imu.csv").write_text("timestamp,gyro_z\n")
    with pytest.warns(UserWarning, match=r"imu\.csv: no samples"):
        check_sequence(root)   # before: "gyro timestamps are empty" from the fusion, no file named
