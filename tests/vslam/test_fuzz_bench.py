"""`vslam bench fuzz` on a few cases: every case is counted, none is a traceback or a hang; a plain exception is a
traceback, a slow case a hang."""
import argparse
import json
import time

import vslam.bench.fuzz as fuzz
from loops.errors import LoopsError


def args(tmp_path, **kw):
    a = argparse.Namespace(blobs=40, sequences=6, configs=6, graphs=0, seed=3, hang_seconds=5.0, kill_seconds=30.0,
                           quick=False, json=str(tmp_path / "fuzz.json"))
    for k, v in kw.items():
        setattr(a, k, v)
    return a


def test_small_fuzz_counts_every_case_without_tracebacks(tmp_path):
    res = fuzz.run(args(tmp_path))
    data = json.loads((tmp_path / "fuzz.json").read_text())
    for name, n in (("descriptor blobs", 40), ("sequence folders", 6), ("pipeline configs", 6)):
        d = data[name]
        assert d["cases"] == n == sum(d[k] for k in fuzz.OUTCOMES)
        assert d["traceback"] == 0 and d["hang"] == 0, d["examples"]
    assert res.exit_code == 0 and "| descriptor blobs | 40 |" in res.markdown


def test_outcomes_of_one_case():
    def plain():
        raise ValueError("a bug")

    def typed():
        raise LoopsError("/x/file.bin: bad field")

    def slow():
        time.sleep(0.3)

    assert fuzz.run_case(plain, 5.0, 30.0, None)[0] == "traceback"
    assert fuzz.run_case(typed, 5.0, 30.0, "/x/file.bin")[::3] == ("typed_error", True)
    assert fuzz.run_case(typed, 5.0, 30.0, "/y/other")[::3] == ("typed_error", False)
    assert fuzz.run_case(slow, 0.1, 30.0, None)[0] == "hang"
    assert fuzz.run_case(lambda: time.sleep(5), 0.1, 0.2, None)[0] == "hang"    # cut at the kill limit
