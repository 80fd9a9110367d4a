"""Truncated and corrupt image files: detected, named, never used as normal frames; decoder messages name the file."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from vslam.bench.fuzz_cases import texture
from vslam.cli.main import main
from vslam.errors import ImageReadError
from vslam.image_file import read_image_file, truncation_problem
from vslam.io import open_sequence

CAMERA_YAML = ("width: 320\nheight: 240\nfx: 300.0\nfy: 300.0\ncx: 160.0\ncy: 120.0\n"
               "distortion: [0, 0, 0, 0, 0]\ncamera_height: 0.3\n")


def jpeg_sequence(root: Path, n: int = 4) -> Path:
    (root / "img").mkdir(parents=True)
    (root / "camera.yaml").write_text(CAMERA_YAML)
    rows = ["timestamp,image"]
    for i in range(n):
        cv2.imwrite(str(root / "img" / f"{i}.jpg"), texture(i))
        rows.append(f"{0.1 * i:.1f},img/{i}.jpg")
    (root / "frames.csv").write_text("\n".join(rows) + "\n")
    return root


def cut_to_a_third(p: Path) -> None:
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 3])


def test_a_jpeg_cut_to_a_third_is_refused_naming_the_file(tmp_path):
    root = jpeg_sequence(tmp_path / "s")
    cut_to_a_third(root / "img" / "2.jpg")
    assert cv2.imread(str(root / "img" / "2.jpg")) is not None    # what OpenCV alone does: a grey-filled frame
    seq = open_sequence(root)
    seq.image(1)
    with pytest.raises(ImageReadError, match=r"2\.jpg: truncated JPEG"):
        seq.image(2)


def test_info_decode_reports_the_truncated_file_invalid(tmp_path, capfd):
    root = jpeg_sequence(tmp_path / "s")
    cut_to_a_third(root / "img" / "2.jpg")
    assert main(["info", str(root), "--decode"]) == 2
    err = capfd.readouterr().err
    assert "frames.csv:4" in err and "2.jpg" in err and "truncated JPEG" in err
    # libjpeg's own message ("Premature end of JPEG file") never reaches the console without the file name
    assert all("2.jpg" in line or "JPEG" not in line for line in err.splitlines())


def test_a_truncated_png_is_detected(tmp_path):
    ok, buf = cv2.imencode(".png", texture(3))
    data = buf.tobytes()
    assert truncation_problem(data) is None
    p = tmp_path / "a.png"
    p.write_bytes(data[: len(data) // 3])
    with pytest.raises(ImageReadError, match="a.png: truncated PNG"):
        read_image_file(p)


def test_decoder_warnings_name_the_file(tmp_path, capfd):
    ok, buf = cv2.imencode(".jpg", texture(1))
    d = bytearray(buf.tobytes())
    sos = d.rfind(b"\xff\xda")
    for k in range(sos + 200, len(d) - 10, 97):    # restart markers where none belong: libjpeg complains
        d[k], d[k + 1] = 0xFF, 0xD3
    p = tmp_path / "corrupt.jpg"
    p.write_bytes(bytes(d))
    with pytest.warns(UserWarning, match=r"corrupt\.jpg: Corrupt JPEG data"):
        img = read_image_file(p)
    assert img.shape == (240, 320, 3)
    assert "Corrupt JPEG" not in capfd.readouterr().err


def test_complete_files_are_not_flagged():
    for ext in (".jpg", ".png"):
        ok, buf = cv2.imencode(ext, texture(2))
        assert truncation_problem(buf.tobytes()) is None
    assert truncation_problem(np.zeros(10, np.uint8).tobytes()) is None   # not JPEG/PNG: left to the decoder


def test_info_decode_on_an_image_folder_names_the_truncated_file(tmp_path, capsys):
    root = jpeg_sequence(tmp_path / "s")
    (root / "frames.csv").unlink()          # a plain image folder now
    (root / "camera.yaml").rename(tmp_path / "camera.yaml")
    cut_to_a_third(root / "img" / "1.jpg")
    assert main(["info", str(root / "img"), "--camera", str(tmp_path / "camera.yaml")]) == 0
    assert main(["info", str(root / "img"), "--camera", str(tmp_path / "camera.yaml"), "--decode"]) == 2
    assert "1.jpg: truncated JPEG" in capsys.readouterr().err
