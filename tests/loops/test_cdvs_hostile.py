"""Hostile descriptor blobs: CRC-valid headers that disagree with the trained model, and property tests that only
the documented errors (LoopsError) escape decode and match."""
import random
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from loops.cdvs import DescriptorDecodeError, decode
from loops.cdvs.codec import CRC_SIZE, HEADER_SIZE, MAX_LOCAL
from loops.cdvs.match import match
from loops.cdvs.trained import load_trained
from loops.errors import LoopsError
from vslam.bench.fuzz_cases import descriptor_blob, seed_descriptors, with_crc

K_OFFSET = 17    # byte offset of the codebook size K in the v1 header
N_OFFSET = 12    # number of local features (16 bit)


@pytest.fixture(scope="module")
def seeds():
    return seed_descriptors(1)


def _with_byte(blob: bytes, offset: int, value: int) -> bytes:
    body = bytearray(blob[:-CRC_SIZE])
    body[offset] = value
    return with_crc(bytes(body))


def test_a_codebook_size_other_than_the_model_is_a_decode_error(seeds):
    k = load_trained().n_clusters
    blob = _with_byte(seeds[3], K_OFFSET, k - 1)    # one cluster fewer: the mask is still the same length
    assert struct.unpack_from(">B", blob, K_OFFSET)[0] == k - 1
    with pytest.raises(DescriptorDecodeError, match="codebook size K"):
        d = decode(blob)
        match(d, decode(seeds[3]))    # before the fix: a plain ValueError (broadcast 63 vs 64) from here


def test_too_many_local_features_is_a_decode_error(seeds):
    body = bytearray(seeds[0][:-CRC_SIZE])
    struct.pack_into(">H", body, N_OFFSET, MAX_LOCAL + 1)
    with pytest.raises(DescriptorDecodeError):
        decode(with_crc(bytes(body)))


def test_a_zero_descriptor_length_is_refused_even_without_features(seeds):
    body = bytearray(seeds[0][:HEADER_SIZE])
    struct.pack_into(">H", body, N_OFFSET, 0)
    body[14] = 0   # desc bytes
    with pytest.raises(DescriptorDecodeError):
        decode(with_crc(bytes(body)))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_only_documented_errors_escape_decode_and_match(seeds, seed):
    blob = descriptor_blob(random.Random(seed), seeds)
    ref = decode(seeds[3])
    try:
        d = decode(blob)
        match(d, ref)
        match(ref, d)
        match(d, d)
    except LoopsError:
        pass


@settings(max_examples=100, deadline=None)
@given(data=st.binary(max_size=300))
def test_random_bytes_decode_or_raise_the_decode_error(data):
    try:
        decode(data)
    except DescriptorDecodeError:
        pass
