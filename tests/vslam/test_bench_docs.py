"""Benchmarks write their tables into docs/benchmarks.md between their markers; the registry and `vslam bench`."""
from __future__ import annotations

import argparse
import datetime
import subprocess
import sys

import pytest

from vslam.bench.docs import markers, publish, replace_section, section_body
from vslam.bench.registry import BENCHMARKS, Benchmark
from vslam.bench.results import BenchResult
from vslam.cli.main import main

TABLE = "| a | b |\n|---|---|\n| 1 | 2 |"
DAY = datetime.date(2025, 1, 2)


# A benchmark for the tests: `vslam bench fake` runs this module.
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rows", type=int, default=1)


def run(args: argparse.Namespace) -> BenchResult:
    print("fake benchmark ran")
    return BenchResult("\n".join([TABLE] + [f"| {i} | {i} |" for i in range(2, args.rows + 1)]))


@pytest.fixture
def fake(monkeypatch):
    monkeypatch.setitem(BENCHMARKS, "fake", Benchmark("fake", __name__, "a benchmark for the tests"))


def _docs(tmp_path, name="fake", before="# Benchmarks\n\nintro\n\n", after="\n\nmore text\n"):
    begin, end = markers(name)
    path = tmp_path / "benchmarks.md"
    path.write_text(f"{before}{begin}\nold table\n{end}{after}")
    return path


def test_section_is_replaced_between_its_markers_only(tmp_path):
    path = _docs(tmp_path)
    note = publish("fake", TABLE, "vslam bench fake --quick", path=path, date=DAY)
    text = path.read_text()
    assert note == f"docs: wrote the fake tables into {path}"
    assert text == ("# Benchmarks\n\nintro\n\n<!-- bench:fake -->\n"
                    "Made by `vslam bench fake --quick` on 2025-01-02.\n\n" + TABLE + "\n<!-- /bench:fake -->"
                    "\n\nmore text\n")
    publish("fake", TABLE + "\n| 3 | 4 |", "vslam bench fake", path=path, date=DAY)   # idempotent shape
    assert path.read_text().count("<!-- bench:fake -->") == 1 and "| 3 | 4 |" in path.read_text()
    assert "old table" not in path.read_text()


def test_other_sections_are_left_alone(tmp_path):
    begin, end = markers("odometry")
    path = _docs(tmp_path, after=f"\n\n{begin}\nodometry table\n{end}\n")
    publish("fake", TABLE, "vslam bench fake", path=path, date=DAY)
    assert f"{begin}\nodometry table\n{end}\n" in path.read_text()


def test_default_writes_only_where_markers_exist_and_never_fails_without_the_file(tmp_path):
    absent = tmp_path / "missing.md"
    assert publish("fake", TABLE, "cmd", path=absent) is None and not absent.exists()
    assert publish("fake", TABLE, "cmd", docs=True, path=absent) == f"docs: {absent} not found; tables not written there"
    assert not absent.exists()
    plain = tmp_path / "plain.md"
    plain.write_text("# Benchmarks\n")
    assert publish("fake", TABLE, "cmd", path=plain) is None
    assert plain.read_text() == "# Benchmarks\n"
    assert publish("fake", TABLE, "cmd", docs=True, path=plain, date=DAY) is not None   # --docs appends
    assert plain.read_text() == ("# Benchmarks\n\n<!-- bench:fake -->\n" + section_body(TABLE, "cmd", DAY)
                                 + "<!-- /bench:fake -->\n")
    marked = _docs(tmp_path)
    assert publish("fake", TABLE, "cmd", docs=False, path=marked) is None and "old table" in marked.read_text()
    assert publish("fake", None, "cmd", docs=True, path=marked) is None


def test_a_closing_marker_before_the_opening_one_is_no_section():
    begin, end = markers("fake")
    assert replace_section(f"{end}\n{begin}\n", "fake", "body\n") is None


def test_vslam_bench_writes_the_docs_with_its_command(fake, tmp_path, capsys):
    path = _docs(tmp_path)
    assert main(["bench", "fake", "--rows", "3", "--docs-file", str(path)]) == 0
    out = capsys.readouterr().out
    assert "fake benchmark ran" in out and f"docs: wrote the fake tables into {path}" in out
    text = path.read_text()
    assert f"Made by `vslam bench fake --rows 3 --docs-file {path}` on {datetime.date.today().isoformat()}." in text
    assert "| 3 | 3 |" in text and "old table" not in text
    assert main(["bench", "fake", "--rows", "4", "--no-docs", "--docs-file", str(path)]) == 0
    assert "| 4 | 4 |" not in path.read_text()
    assert main(["bench", "fake", "--docs-file", str(tmp_path / "absent.md")]) == 0
    assert "docs:" not in capsys.readouterr().out


def test_every_registered_benchmark_loads_and_parses_its_help(capsys):
    assert sorted(BENCHMARKS) == ["batch", "descriptors", "fuzz", "graph", "horizon", "localize", "loops", "odometry",
                                  "paper", "pipeline"]
    for name, bench in BENCHMARKS.items():
        mod = bench.load()
        assert callable(mod.add_arguments) and callable(mod.run)
        with pytest.raises(SystemExit) as exc:
            main(["bench", name, "--help"])
        assert exc.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: vslam bench {name}") and "--docs, --no-docs" in out


def test_building_the_command_line_imports_no_benchmark():
    code = ("import sys; from vslam.cli.main import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules if m.startswith('vslam.bench.') or m == 'graph'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['vslam.bench.docs', 'vslam.bench.registry']"
