"""The floor vocabulary shipped in loops/data: small, loadable, and rebuilt by its entry point (byte for byte with
the same OpenCV and numpy; the check here is the structure, which does not depend on their versions)."""
from pathlib import Path

from loops.vocab import DescriptorName, load_floor_vocabulary
from loops.vocab.floor_vocabulary import FLOOR_VOCABULARY, main

TEXTURES = Path(__file__).resolve().parents[2] / "vslam" / "data" / "textures"


def test_the_shipped_vocabulary_is_small_and_loads():
    assert FLOOR_VOCABULARY.stat().st_size < 150_000
    tree, params = load_floor_vocabulary()
    assert params.descriptor is DescriptorName.ORB and tree.n_words == 1000 and tree.dim == 32


def test_the_entry_point_rebuilds_it(tmp_path, capsys):
    out = tmp_path / "floor.voc"
    assert main([str(TEXTURES), str(out)]) == 0
    assert "1000 words" in capsys.readouterr().out
    tree, params = load_floor_vocabulary(out)
    shipped, shipped_params = load_floor_vocabulary()
    assert params == shipped_params and tree.children.shape == shipped.children.shape
