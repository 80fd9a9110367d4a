"""The floor vocabulary shipped in loops/data: small, loadable, and rebuilt byte for byte by its entry point."""
from pathlib import Path

from loops.vocab import DescriptorName, load_floor_vocabulary
from loops.vocab.floor_vocabulary import FLOOR_VOCABULARY, main

TEXTURES = Path(__file__).resolve().parents[2] / "vslam" / "data" / "textures"


def test_the_shipped_vocabulary_is_small_and_loads():
    assert FLOOR_VOCABULARY.stat().st_size < 150_000
    tree, params = load_floor_vocabulary()
    assert params.descriptor is DescriptorName.ORB and tree.n_words == 1000 and tree.dim == 32


def test_the_entry_point_rebuilds_it_exactly(tmp_path, capsys):
    out = tmp_path / "floor.voc"
    assert main([str(TEXTURES), str(out)]) == 0
    assert out.read_bytes() == FLOOR_VOCABULARY.read_bytes()
    assert "1000 words" in capsys.readouterr().out
