"""Generators of malformed inputs for the hostile-input fuzz (`vslam bench fuzz`) and the property tests.

Each generator is structure-aware: it starts from a valid input and breaks one or a few of its parts, so most
cases pass the outer checks (CRC, CSV header, YAML syntax) and reach the validation behind them. All are seeded
(`random.Random`), so a failing case is reproduced from its index.
"""
from __future__ import annotations

import copy
import json
import random
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from loops.cdvs.codec import CRC_SIZE, HEADER_SIZE, encode_all_modes

# descriptor header fields (loops.cdvs.codec layout v1), with the struct code of each
HEADER_FIELDS = ("magic", "version", "mode", "orig_w", "orig_h", "proc_w", "proc_h", "n_local", "desc_bytes",
                 "coord_block", "rice_k", "clusters", "visited", "flags", "params_id", "unary_len")
_FIELD_CODES = ("2s", "B", "B", "H", "H", "H", "H", "H", "B", "B", "B", "B", "B", "B", "H", "H")
_HEADER_FMT = ">" + "".join(_FIELD_CODES)


def texture(seed: int, h: int = 240, w: int = 320) -> np.ndarray:
    """Seeded multi-scale noise, a stand-in for a floor texture (features everywhere)."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.float32)
    for s, a in ((4, 0.5), (16, 1.0), (64, 0.7)):
        small = rng.random((max(2, h // s), max(2, w // s))).astype(np.float32)
        img += a * cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    img = (img - img.min()) / (img.max() - img.min() + 1e-6)
    return (img * 230 + 10).astype(np.uint8)


def seed_descriptors(n_images: int = 2) -> list[bytes]:
    """Valid descriptor blobs of every mode for a few textures: the starting points of the mutations."""
    out: list[bytes] = []
    for s in range(n_images):
        out += list(encode_all_modes(texture(s)).values())
    return out


def with_crc(body: bytes) -> bytes:
    return body + struct.pack(">I", zlib.crc32(body))


def _field_value(rng: random.Random, code: str, old):
    if code == "2s":
        return rng.choice([b"CD", b"CE", b"\x00\x00", bytes([rng.randrange(256), rng.randrange(256)])])
    top = 255 if code == "B" else 65535
    choices = [0, 1, 2, top, top - 1, rng.randrange(top + 1), max(0, old - 1), min(top, old + 1),
               min(top, old * 2), old // 2, 64, 8, 32, 33, 7, 300, 4096]
    return min(top, rng.choice(choices))


def descriptor_blob(rng: random.Random, seeds: list[bytes]) -> bytes:
    """A structure-aware malformed descriptor: a valid blob with one to three header fields changed, or body bytes
    flipped, truncated or extended; most cases are then made length- and CRC-consistent so that they reach the
    checks behind the checksum."""
    base = bytearray(rng.choice(seeds)[:-CRC_SIZE])
    kind = rng.random()
    fields = list(struct.unpack_from(_HEADER_FMT, base))
    if kind < 0.7:                                         # header fields
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(fields))
            fields[i] = _field_value(rng, _FIELD_CODES[i], fields[i] if _FIELD_CODES[i] != "2s" else 0)
        base[:HEADER_SIZE] = struct.pack(_HEADER_FMT, *fields)
    elif kind < 0.85:                                      # body bytes
        for _ in range(rng.randint(1, 8)):
            j = rng.randrange(HEADER_SIZE, max(HEADER_SIZE + 1, len(base)))
            if j < len(base):
                base[j] = rng.randrange(256)
    else:                                                  # length
        if rng.random() < 0.5:
            base = base[: rng.randrange(len(base) + 1)]
        else:
            base += bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
    if rng.random() < 0.8 and len(base) >= HEADER_SIZE:    # make the length agree with the header
        (_, _, _, _, _, _, _, n, dbytes, _, rk, k, n_vis, _, _, unary_len) = struct.unpack_from(_HEADER_FMT, base)
        want = HEADER_SIZE + -(-k // 8) + n_vis * 4 + unary_len + -(-(n * rk) // 8) + n * dbytes
        if want <= 20000:
            base = base[:want] + bytes(rng.randrange(256) for _ in range(max(0, want - len(base))))
    return with_crc(bytes(base)) if rng.random() < 0.9 else bytes(base) + bytes(rng.randrange(256) for _ in range(4))


# ---- sequence directories ----------------------------------------------------------------------------------------
CAMERA_YAML = ("width: 64\nheight: 48\nfx: 60.0\nfy: 60.0\ncx: 32.0\ncy: 24.0\ndistortion: [0, 0, 0, 0, 0]\n"
               "camera_height: 0.3\n")


def _image_bytes(rng: random.Random, w: int = 64, h: int = 48, ext: str = ".png") -> bytes:
    img = texture(rng.randrange(1000), h, w)
    ok, buf = cv2.imencode(ext, img)
    assert ok
    return buf.tobytes()


def mutate_text(rng: random.Random, text: str) -> str:
    """One textual mutation of a small file: a line dropped, duplicated or swapped, a cell replaced by a hostile
    token, characters inserted or deleted, the file truncated."""
    lines = text.split("\n")
    tokens = ["", "nan", "inf", "-inf", "-1", "0", "1e309", "abc", "1,2", '"', "\x00", "\ufeff", "  ", "1e-320",
              "[1, 2", "{}", "- x", ":", "#", "9" * 40, "ü", "\r", "true", "null"]
    op = rng.randrange(7)
    if op == 0 and lines:
        del lines[rng.randrange(len(lines))]
    elif op == 1 and lines:
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    elif op == 2 and len(lines) > 1:
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif op == 3 and lines:
        i = rng.randrange(len(lines))
        sep = "," if "," in lines[i] else (": " if ": " in lines[i] else " ")
        cells = lines[i].split(sep)
        cells[rng.randrange(len(cells))] = rng.choice(tokens)
        lines[i] = sep.join(cells)
    elif op == 4:
        s = "\n".join(lines)
        k = rng.randrange(len(s) + 1)
        return s[:k] + rng.choice(tokens) + s[k:]
    elif op == 5:
        s = "\n".join(lines)
        return s[: rng.randrange(len(s) + 1)]
    else:
        s = "\n".join(lines)
        k = rng.randrange(len(s) + 1)
        return s[:k] + s[k + rng.randint(1, 5):]
    return "\n".join(lines)


def sequence_folder(rng: random.Random, root: Path, n_frames: int = 3, corrupt: bool = True) -> Path:
    """A small sequence directory (camera.yaml, frames.csv, images, odometry.csv, imu.csv, groundtruth.txt) with one
    to three of its files broken (unless not `corrupt`): text mutated, an image missing, truncated, empty or not an
    image."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "images").mkdir(exist_ok=True)
    files = {"camera.yaml": CAMERA_YAML}
    ts = [0.1 * i for i in range(n_frames)]
    rows = ["timestamp,image"]
    for i, t in enumerate(ts):
        name = f"images/{i:06d}.png"
        (root / name).write_bytes(_image_bytes(rng))
        rows.append(f"{t:.3f},{name}")
    files["frames.csv"] = "\n".join(rows) + "\n"
    files["odometry.csv"] = "timestamp,v,omega\n" + "".join(f"{t:.3f},0.1,0.0\n" for t in ts)
    files["imu.csv"] = "timestamp,gyro_z\n" + "".join(f"{t:.3f},0.0\n" for t in ts)
    files["groundtruth.txt"] = "".join(f"{t:.3f} {0.01 * i:.3f} 0 0 0 0 0 1\n" for i, t in enumerate(ts))
    for _ in range(rng.randint(1, 3) if corrupt else 0):
        target = rng.choice(list(files) + ["image"])
        if target == "image":
            p = root / f"images/{rng.randrange(n_frames):06d}.png"
            op = rng.randrange(4)
            if op == 0:
                p.unlink(missing_ok=True)
            elif op == 1 and p.exists():
                data = p.read_bytes()
                p.write_bytes(data[: len(data) // 3])
            elif op == 2:
                p.write_bytes(b"")
            else:
                p.write_bytes(b"not an image" * rng.randint(1, 10))
        elif rng.random() < 0.1:
            files.pop(target)
        else:
            files[target] = mutate_text(rng, files[target])
    for name, text in files.items():
        (root / name).write_text(text, encoding="utf-8", errors="surrogatepass")
    return root


# ---- configs -----------------------------------------------------------------------------------------------------
def config_text(rng: random.Random, valid_yaml: str) -> str:
    """A pipeline config (YAML) with one to three mutations: a value replaced by a hostile token, a key misspelt,
    a line dropped or duplicated, characters inserted."""
    text = valid_yaml
    for _ in range(rng.randint(1, 3)):
        text = mutate_text(rng, text)
    return text


# ---- JSON documents and binary files with a JSON header ----------------------------------------------------------
HOSTILE_JSON_VALUES = (None, -1, 0, 1, 2, 10**9, -(10**9), 1.5, float("nan"), float("inf"), "x", "", [], {}, True,
                       [1, 2], [-1], "<u1", "|u1", "<f8", [[1]], 2**70)


def json_paths(x, path: tuple = ()) -> list[tuple]:
    """Paths to every leaf (and every container) of a JSON document."""
    out = [path]
    if isinstance(x, dict):
        for k, v in x.items():
            out += json_paths(v, path + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out += json_paths(v, path + (i,))
    return out


def mutate_json(rng: random.Random, doc, n: int | None = None):
    """A copy of a JSON document with one to three values replaced by hostile ones or deleted."""
    doc = copy.deepcopy(doc)
    for _ in range(n or rng.randint(1, 3)):
        paths = [p for p in json_paths(doc) if p]
        if not paths:
            return rng.choice(HOSTILE_JSON_VALUES)
        p = rng.choice(paths)
        node = doc
        for k in p[:-1]:
            node = node[k]
        if rng.random() < 0.15:
            del node[p[-1]]
        else:
            node[p[-1]] = rng.choice(HOSTILE_JSON_VALUES)
    return doc


def split_array_file(buf: bytes) -> tuple[dict, bytes]:
    """(JSON header, data) of a vocabulary/memory file (loops.vocab.fileformat layout)."""
    (hlen,) = struct.unpack_from("<I", buf, 12)
    start = 16 + hlen + (-(16 + hlen)) % 64
    return json.loads(buf[16:16 + hlen]), buf[start:]


def join_array_file(header: dict, data: bytes) -> bytes:
    """Reassemble a vocabulary/memory file around a (changed) header: the data and its checksum stay valid."""
    hb = json.dumps(header).encode()
    head = b"VSLMVOC\0" + struct.pack("<II", 1, len(hb)) + hb
    return head + b"\0" * ((-len(head)) % 64) + data


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    """Bytes flipped, a slice cut out, or the tail cut off."""
    b = bytearray(data)
    op = rng.randrange(3)
    if op == 0 and b:
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == 1 and b:
        i = rng.randrange(len(b))
        del b[i:i + rng.randint(1, 64)]
    else:
        b = b[: rng.randrange(len(b) + 1)]
    return bytes(b)
