#!/usr/bin/env python3
"""Writes the compressed-frame fixtures of `crates/io/src/dicom/tests.rs` (issue 28): small
grey-scale codestreams made by reference encoders, with what the reference decoders read from
them, so that volsplat's pure-Rust decoders are compared with OpenJPEG, CharLS and
libjpeg-turbo (through `imagecodecs`) on the same bytes.

    python3 -m venv /tmp/dcmvenv && /tmp/dcmvenv/bin/pip install numpy imagecodecs
    /tmp/dcmvenv/bin/python crates/io/src/dicom/testdata/make_codec_fixtures.py

Each fixture is `NAME.bin` (the codestream, as one DICOM pixel data fragment holds it) and
`NAME.i32` (the samples the reference decoder reads: little-endian i32, row by row). The source
image is `ramp(rows, cols, bits, signed)` below; lossless fixtures decode to it exactly.
"""

from pathlib import Path

import imagecodecs as ic
import numpy as np

HERE = Path(__file__).parent
ROWS, COLS = 20, 24


def ramp(bits: int, signed: bool) -> np.ndarray:
    """A smooth ramp plus a few edges and a checker patch, covering the value range."""
    y, x = np.mgrid[0:ROWS, 0:COLS]
    top = (1 << bits) - 1
    v = (x * 97 + y * 131 + (x * y) % 17 * 23) % (top + 1)
    v[5:9, 5:11] = ((x[5:9, 5:11] + y[5:9, 5:11]) % 2) * top
    v = v.astype(np.int64)
    if signed:
        v -= 1 << (bits - 1)
    return v


def write(name: str, stream: bytes, decoded: np.ndarray) -> None:
    (HERE / f"{name}.bin").write_bytes(stream)
    (HERE / f"{name}.i32").write_bytes(decoded.astype("<i4").tobytes())
    print(f"{name}: {len(stream)} bytes, decoded range {decoded.min()}..{decoded.max()}")


def main() -> None:
    # JPEG 2000 lossless (reversible 5/3), 16-bit signed (CT-like), raw codestream.
    src = ramp(16, True).astype(np.int16)
    s = ic.jpeg2k_encode(src, level=0, codecformat="J2K", reversible=True)
    d = ic.jpeg2k_decode(s)
    assert np.array_equal(d, src)
    write("j2k_lossless_s16", s, d)
    # JPEG 2000 lossy (irreversible 9/7), 12 bits in 16, unsigned.
    src = ramp(12, False).astype(np.uint16)
    s = ic.jpeg2k_encode(src, level=30, codecformat="J2K", reversible=False, bitspersample=12)
    write("j2k_lossy_u12", s, ic.jpeg2k_decode(s))
    # JPEG-LS lossless 16-bit, and near-lossless (NEAR 2) 8-bit.
    src = ramp(16, False).astype(np.uint16)
    s = ic.jpegls_encode(src, level=0)
    d = ic.jpegls_decode(s)
    assert np.array_equal(d, src)
    write("jls_lossless_u16", s, d)
    src = ramp(8, False).astype(np.uint8)
    s = ic.jpegls_encode(src, level=2)
    write("jls_near2_u8", s, ic.jpegls_decode(s))
    # JPEG extended (process 4), 12-bit DCT.
    src = ramp(12, False).astype(np.uint16)
    s = ic.jpeg8_encode(src, level=90, bitspersample=12)
    assert s[2:4] != b"" and b"\xff\xc1" in s[:400], "expected an SOF1 frame header"
    write("jpeg_extended_u12", s, ic.jpeg8_decode(s))
    # JPEG lossless (process 14, first-order prediction), 12 bits.
    s = ic.jpeg8_encode(src, lossless=True, predictor=1, bitspersample=12)
    d = ic.jpeg8_decode(s)
    assert np.array_equal(d, src)
    write("jpeg_lossless_u12", s, d)


if __name__ == "__main__":
    main()
