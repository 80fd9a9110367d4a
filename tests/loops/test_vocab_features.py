import cv2
import numpy as np
import pytest

from loops.vocab import GrayscaleImageError, NoFeaturesError, extract, is_grayscale, preset
from loops.vocab.brief import brief_describe, brief_pattern, rotated_offsets
from loops.vocab.features import color_patches

from ._vocab_helpers import texture


def test_brief_is_deterministic_and_256_bits():
    img = texture(1)
    p = preset("fast", descriptor="brief")
    a, b = extract(img, p)[0], extract(img, p)[0]
    assert a.dtype == np.uint8 and a.shape[1] == 32 and len(a) > 20
    assert np.array_equal(a, b)


def test_rotated_pattern_equals_plain_pattern_on_the_rotated_image():
    """BRIEFROT's premise: the key descriptor with the pattern turned by -phi is what the plain pattern gives on the
    image turned by +phi (OpenCV sign)."""
    img = cv2.cvtColor(texture(3, 240, 240), cv2.COLOR_BGR2GRAY)
    smooth = cv2.GaussianBlur(img, (0, 0), 2.0)
    phi = 15.0
    m = cv2.getRotationMatrix2D((119.5, 119.5), phi, 1.0)
    rot = cv2.GaussianBlur(cv2.warpAffine(img, m, (240, 240)), (0, 0), 2.0)
    rng = np.random.default_rng(0)
    p = rng.integers(90, 150, (60, 2)).astype(float)
    q = np.rint(p @ m[:, :2].T + m[:, 2]).astype(np.int32)
    p = p.astype(np.int32)
    pattern = brief_pattern(32, 1234)
    plain_q = brief_describe(rot, q, rotated_offsets(pattern, 0.0))

    def mean_hamming(d):
        return np.unpackbits(d ^ plain_q, axis=1).sum(1).mean()

    matched = mean_hamming(brief_describe(smooth, p, rotated_offsets(pattern, -phi)))
    plain = mean_hamming(brief_describe(smooth, p, rotated_offsets(pattern, 0.0)))
    wrong = mean_hamming(brief_describe(smooth, p, rotated_offsets(pattern, phi)))
    assert matched < 0.5 * plain and matched < 0.5 * wrong


def test_briefrot_extracts_the_same_keypoints_at_three_angles():
    p = preset("fast", descriptor="briefrot", rot_theta_deg=10)
    out = extract(texture(2), p, angles=(0.0, 10.0, -10.0))
    assert len(out) == 3 and len({len(d) for d in out}) == 1
    assert not np.array_equal(out[0], out[1])


@pytest.mark.parametrize("name", ["orb", "surf"])
def test_orb_and_sift_descriptors(name):
    d = extract(texture(4), preset("fast", descriptor=name))[0]
    assert len(d) > 10
    assert (d.dtype, d.shape[1]) == ((np.uint8, 32) if name == "orb" else (np.float32, 128))


def test_colour_patch_layouts():
    shape = (480, 640)
    whole = color_patches(shape, preset("default", descriptor="color-whole"))
    half = color_patches(shape, preset("default", descriptor="color-half"))
    rand = color_patches(shape, preset("default", descriptor="color-random"))
    assert len(whole) == len(half) == 19 * 19 and len(rand) == 500
    assert tuple(whole[0]) == (0, 0, 64, 48) and tuple(whole[1]) == (32, 0, 64, 48)   # half-overlapping
    assert (half[:, 1] + half[:, 3]).max() <= 240                                      # upper half only
    assert np.all(rand[:, 2:] == (64, 48))
    d = extract(texture(5, 240, 320), preset("default", descriptor="color-whole"))[0]
    assert d.shape == (361, 64) and np.allclose(d.sum(1), 1.0)


def test_colour_vocabularies_refuse_grayscale_images_clearly():
    gray = texture(6, color=False)
    assert is_grayscale(gray) and is_grayscale(cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    assert not is_grayscale(texture(6))
    with pytest.raises(GrayscaleImageError, match="frame7.png: is a grayscale image; the color-half vocabulary"):
        extract(gray, preset("fast", descriptor="color-half"), name="frame7.png")


@pytest.mark.parametrize("name", ["brief", "orb", "surf"])
def test_blank_image_has_no_features(name):
    with pytest.raises(NoFeaturesError, match="blank.png: no"):
        extract(np.full((120, 160), 128, np.uint8), preset("fast", descriptor=name), name="blank.png")


def test_mask_restricts_keypoints():
    img = texture(7)
    mask = np.zeros(img.shape[:2], np.uint8)
    with pytest.raises(NoFeaturesError):
        extract(img, preset("fast", descriptor="brief"), mask=mask)
    mask[:, :100] = 255
    assert 0 < len(extract(img, preset("fast", descriptor="brief"), mask=mask)[0])
