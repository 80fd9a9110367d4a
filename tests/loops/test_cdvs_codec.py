"""Compact descriptor codec: round trip, hard budget, malformed input."""
import struct
import zlib

import cv2
import numpy as np
import pytest

from loops.cdvs import BUDGETS, MODES, DescriptorDecodeError, decode, encode, encode_all_modes
from loops.cdvs.codec import HEADER_SIZE
from vslam.bench.fuzz_cases import texture as fuzz_texture


def texture(seed: int, h: int = 480, w: int = 640) -> np.ndarray:
    """The fuzz cases' seeded multi-scale noise (a stand-in for a floor texture) at the codec's 640x480."""
    return fuzz_texture(seed, h, w)


@pytest.fixture(scope="module")
def descs():
    img = texture(1)
    return {m: encode(img, m) for m in MODES}


def test_round_trip_fields(descs):
    for m, data in descs.items():
        d = decode(data)
        assert d.mode == m and d.nbytes == len(data) <= BUDGETS[m]
        assert d.image_size == (640, 480) and d.proc_size == (640, 480)
        assert d.n_local > 10, f"mode {m}: only {d.n_local} local features on a textured image"
        assert np.all((d.keypoints >= -0.5) & (d.keypoints <= [639.5, 479.5]))
        assert d.local.shape == (d.n_local, d.desc_bits // 8)
        assert d.global_visited.any()
        assert np.all(d.global_bits[~d.global_visited] == 0)
    # more budget -> more features
    n = [decode(descs[m]).n_local for m in MODES]
    assert n == sorted(n) and n[-1] > 3 * n[0]


def test_encoding_is_deterministic_and_matches_shared_extraction(descs):
    img = texture(1)
    assert encode(img, 3) == descs[3]
    assert encode_all_modes(img) == descs


def test_keypoints_map_back_to_the_original_resolution():
    img = texture(2, 960, 1280)
    d = decode(encode(img, 5))
    assert d.image_size == (1280, 960) and d.proc_size == (640, 480)
    assert d.keypoints[:, 0].max() > 700 and d.keypoints[:, 1].max() > 500   # original pixels, not resized ones
    assert np.allclose(d.keypoints, (d.xy + 0.5) * 2 - 0.5)


def test_budget_is_never_exceeded_over_many_images_and_modes():
    rng = np.random.default_rng(7)
    images = [texture(s, int(h), int(w)) for s, (h, w) in enumerate(rng.integers(40, 900, size=(10, 2)))]
    images += [np.zeros((480, 640), np.uint8), np.full((480, 640), 255, np.uint8),
               (rng.random((480, 640)) * 255).astype(np.uint8),                       # pure noise: dense keypoints
               np.kron((np.indices((24, 32)).sum(0) % 2) * 255, np.ones((20, 20))).astype(np.uint8),  # checkerboard
               texture(99, 16, 16), texture(98, 2000, 300)]
    for img in images:
        for m, data in encode_all_modes(img).items():
            assert len(data) <= BUDGETS[m], (img.shape, m, len(data))
            decode(data)  # and every one decodes


def test_blank_image_gives_an_empty_but_valid_descriptor():
    d = decode(encode(np.full((480, 640), 128, np.uint8), 2))
    assert d.n_local == 0 and not d.global_visited.any()


def test_colour_and_float_images_are_accepted():
    g = texture(3)
    bgr = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
    assert decode(encode(bgr, 2)).n_local == decode(encode(g, 2)).n_local
    assert decode(encode(g.astype(np.float32) / 255.0, 2)).n_local > 0


@pytest.mark.parametrize("bad", [np.zeros((5, 5), np.uint8), np.zeros((10, 10, 2), np.uint8),
                                 np.zeros((64, 64), np.int32), np.zeros(100, np.uint8)])
def test_bad_images_raise_value_error(bad):
    with pytest.raises(ValueError):
        encode(bad, 1)


def test_bad_mode_raises():
    with pytest.raises(ValueError, match="mode"):
        encode(texture(1), 7)


def test_truncation_at_every_length_raises_typed_error(descs):
    for m in (1, 6):
        data = descs[m]
        lengths = range(len(data)) if m == 1 else list(range(0, 200)) + list(range(len(data) - 200, len(data)))
        for n in lengths:
            with pytest.raises(DescriptorDecodeError):
                decode(data[:n])


def test_every_single_bit_flip_is_detected(descs):
    data = bytearray(descs[1])
    for bit in range(len(data) * 8):
        data[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(DescriptorDecodeError):
            decode(bytes(data))
        data[bit // 8] ^= 1 << (bit % 8)
    decode(bytes(data))


def test_random_and_foreign_bytes_raise_typed_error(descs):
    rng = np.random.default_rng(0)
    for n in (0, 1, 27, 28, 100, 512, 5000):
        with pytest.raises(DescriptorDecodeError):
            decode(rng.integers(0, 256, n, dtype=np.uint8).tobytes())
    for foreign in (b"\x89PNG\r\n\x1a\n" + bytes(100), b"CD" + bytes(60), descs[2] + b"\x00", "text"):
        with pytest.raises(DescriptorDecodeError):
            decode(foreign)
    with pytest.raises(DescriptorDecodeError, match="version"):
        decode(descs[1][:2] + b"\x09" + descs[1][3:])


def _recrc(body: bytes) -> bytes:
    return body + struct.pack(">I", zlib.crc32(body))


def test_crafted_headers_with_valid_crc_are_rejected_without_allocating(descs):
    """A checksum-valid string whose header lies (huge counts, bad sizes) must fail on the length checks."""
    body = bytearray(descs[3][:-4])
    for name, off, val, fmt in [("n_local", 12, 65535, ">H"), ("width", 8, 0, ">H"), ("block", 15, 0, ">B"),
                                ("mode", 3, 9, ">B"), ("visited", 19, 255, ">B"), ("unary", 22, 65535, ">H")]:
        b = bytearray(body)
        struct.pack_into(fmt, b, off, val)
        with pytest.raises(DescriptorDecodeError):
            decode(_recrc(bytes(b)))
    assert HEADER_SIZE == 24


def test_budget_holds_on_random_crops_of_real_textures(shared_data):
    paths = sorted(p for p in (shared_data / "textures").rglob("*") if p.suffix.lower() in (".png", ".jpg"))
    assert paths
    rng = np.random.default_rng(3)
    worst = {m: 0 for m in MODES}
    for k in range(24):
        img = cv2.imread(str(paths[k % len(paths)]), cv2.IMREAD_GRAYSCALE)
        h, w = img.shape
        ch, cw = int(rng.integers(64, h)), int(rng.integers(64, w))
        y, x = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
        crop = cv2.resize(img[y:y + ch, x:x + cw], None, fx=rng.uniform(0.5, 2.0), fy=rng.uniform(0.5, 2.0))
        for m, data in encode_all_modes(crop).items():
            worst[m] = max(worst[m], len(data))
            assert len(data) <= BUDGETS[m]
    assert worst[6] > 4096  # the large modes are actually used, not trivially small


def test_trained_global_weights_never_favour_farther_signatures():
    from loops.cdvs import load_trained

    w = load_trained().global_weights
    assert np.all(np.diff(w) <= 0) and w[0] > 0 > w[-1]
