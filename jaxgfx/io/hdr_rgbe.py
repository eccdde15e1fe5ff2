"""Radiance RGBE (``.hdr`` / ``.pic``) reading and writing in vectorised NumPy (host-only).

Pixel encoding (Ward, "Real Pixels", Graphics Gems II, 1991): a shared exponent
``E = e + 128`` where ``max(R, G, B) = f * 2**e`` with ``f`` in ``[0.5, 1)`` (``frexp``), and 8-bit
mantissas ``M_c = floor(c * 2**(8 - e))`` (computed with an exact ``ldexp``, so the largest
channel's mantissa is in ``[128, 255]``). Pixels whose maximum is below ``2**-127`` (or not
positive) are stored as ``(0, 0, 0, 0)``; negative channels and NaN are stored as 0; values at
or above ``2**128`` saturate to ``(255, 255, 255, 255)``.

Decoding: ``c = (M_c + offset) * 2**(E - 136)`` for ``E > 0``, else 0. The default ``offset=0.5``
is Radiance's own ``colr_color`` convention (centre of the quantisation bin, max relative error
``2**-8`` on the largest channel); ``offset=0.0`` is Bruce Walter's ``rgbe.c`` used by OpenCV
(``cv2.imread`` of a ``.hdr`` file) and reproduces OpenCV's floats exactly (max relative error
``2**-7``, always rounding down).

File layout: a text header starting with ``#?`` (``#?RADIANCE`` or ``#?RGBE``), ``FORMAT=``
``32-bit_rle_rgbe`` (or ``32-bit_rle_xyze``: values are then CIE XYZ, returned unchanged), a
blank line, a resolution line (standard ``-Y H +X W``; the other seven orientations are read
and flipped/transposed to top-to-bottom, left-to-right rows), then scanlines: new-style
run-length encoded (``2 2 hi lo`` marker, widths 8..32767), flat, or old-style RLE
(``1 1 1 n`` repeats the previous pixel). ``EXPOSURE=`` lines are reported by
:func:`read_hdr_header` but not applied (as OpenCV).
"""

from __future__ import annotations

import re

import numpy as np

from ._common import as_image_array, existing_file, output_path

__all__ = [
    "read_hdr",
    "read_hdr_header",
    "write_hdr",
    "rgbe_from_float",
    "float_from_rgbe",
]

_MAX_HEADER = 64 * 1024
_RES_RE = re.compile(rb"^([+-])([XY]) (\d+) ([+-])([XY]) (\d+)$")


def rgbe_from_float(rgb) -> np.ndarray:
    """Encode float RGB ``(..., 3)`` to RGBE bytes ``(..., 4)`` uint8 (Ward 1991, see module)."""
    rgb = np.array(rgb, dtype=np.float64)  # a copy: modified in place below
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"rgb: expected shape (..., 3), got {rgb.shape}")
    bad = ~(rgb >= 0)  # negative or NaN
    if bad.any():
        rgb[bad] = 0.0
    v = rgb.max(axis=-1)
    _, e = np.frexp(v)
    zero = v < 2.0**-127
    sat = v >= 2.0**128
    e = np.where(zero | sat, 0, e)
    rgb *= np.ldexp(256.0, -e)[..., None]  # exact power-of-two scaling: 2**(8 - e)
    np.floor(rgb, out=rgb)
    np.clip(rgb, 0, 255, out=rgb)
    out = np.empty(rgb.shape[:-1] + (4,), np.uint8)
    out[..., :3] = rgb
    out[..., 3] = e + 128
    out[zero] = 0
    out[sat] = 255
    return out


def float_from_rgbe(rgbe, *, offset: float = 0.5) -> np.ndarray:
    """Decode RGBE bytes ``(..., 4)`` to float32 RGB ``(..., 3)``: ``(M + offset) 2**(E-136)``."""
    rgbe = np.asarray(rgbe)
    if rgbe.shape[-1:] != (4,):
        raise ValueError(f"rgbe: expected shape (..., 4), got {rgbe.shape}")
    # float32 is exact here: (M + offset) has <= 9 significant bits and 2**(E - 136) >= 2**-136.
    scale = np.ldexp(np.float32(1.0), np.arange(256) - 136).astype(np.float32)
    scale[0] = 0.0
    m = rgbe[..., :3].astype(np.float32) + np.float32(offset)
    return m * scale[rgbe[..., 3].astype(np.intp)][..., None]


# ----------------------------------------------------------------------------- reading


def _parse_header(data: bytes, p) -> tuple[dict, int]:
    if not data.startswith(b"#?"):
        raise ValueError(f"'{p}': not a Radiance HDR file (header must start with '#?')")
    end = data.find(b"\n\n", 0, _MAX_HEADER)
    if end < 0:
        raise ValueError(f"'{p}': Radiance header not terminated by a blank line")
    lines = data[:end].split(b"\n")
    info: dict = {"program": lines[0][2:].decode("latin-1").strip(), "exposure": 1.0}
    fmt = None
    for line in lines[1:]:
        if line.startswith(b"FORMAT="):
            fmt = line[7:].decode("latin-1").strip()
        elif line.startswith(b"EXPOSURE="):
            try:
                info["exposure"] *= float(line[9:])
            except ValueError:
                raise ValueError(f"'{p}': bad EXPOSURE line {line!r}") from None
    if fmt is None:
        fmt = "32-bit_rle_rgbe"  # Radiance's default when FORMAT is absent
    if fmt not in ("32-bit_rle_rgbe", "32-bit_rle_xyze"):
        raise ValueError(f"'{p}': unsupported FORMAT={fmt!r} (expected 32-bit_rle_rgbe/xyze)")
    info["format"] = fmt
    res_end = data.find(b"\n", end + 2, end + 2 + 256)
    if res_end < 0:
        raise ValueError(f"'{p}': missing resolution line")
    res = data[end + 2 : res_end].strip()
    m = _RES_RE.match(res)
    if m is None or m.group(2) == m.group(5):
        raise ValueError(f"'{p}': bad resolution line {res!r} (expected e.g. '-Y 480 +X 640')")
    info["orientation"] = res.decode()
    info["axes"] = ((m.group(1) + m.group(2)).decode(), (m.group(4) + m.group(5)).decode())
    info["dims"] = (int(m.group(3)), int(m.group(6)))
    if info["dims"][0] <= 0 or info["dims"][1] <= 0:
        raise ValueError(f"'{p}': empty image in resolution line {res!r}")
    return info, res_end + 1


def _decode_rle_line(buf: bytes, pos: int, width: int, y: int, p) -> tuple[bytes, int]:
    """Decode the 4 run-length coded components of one new-style scanline (planar bytes)."""
    size = len(buf)
    line = bytearray()
    end = 0
    for _ in range(4):
        end += width
        while len(line) < end:
            if pos >= size:
                raise ValueError(f"'{p}': file truncated in scanline {y}")
            count = buf[pos]
            if count > 128:
                count -= 128
                if pos + 1 >= size:
                    raise ValueError(f"'{p}': file truncated in scanline {y}")
                if len(line) + count > end:
                    raise ValueError(f"'{p}': bad run length in scanline {y}")
                line += bytes((buf[pos + 1],)) * count
                pos += 2
            else:
                if pos + 1 + count > size:
                    raise ValueError(f"'{p}': file truncated in scanline {y}")
                if count == 0 or len(line) + count > end:
                    raise ValueError(f"'{p}': bad run length in scanline {y}")
                line += buf[pos + 1 : pos + 1 + count]
                pos += 1 + count
    return bytes(line), pos


def _decode_scanlines(buf: bytes, pos: int, n_lines: int, width: int, p) -> np.ndarray:
    """Decode ``n_lines`` scanlines of ``width`` RGBE pixels starting at ``buf[pos]``."""
    out = np.empty((n_lines, width, 4), np.uint8)
    size = len(buf)
    arr = np.frombuffer(buf, np.uint8)
    prev = None
    for y in range(n_lines):
        if pos + 4 > size:
            raise ValueError(f"'{p}': file truncated at scanline {y} of {n_lines}")
        b0, b1, b2, b3 = buf[pos], buf[pos + 1], buf[pos + 2], buf[pos + 3]
        if 8 <= width <= 0x7FFF and b0 == 2 and b1 == 2 and not (b2 & 0x80):
            if (b2 << 8 | b3) != width:
                raise ValueError(
                    f"'{p}': scanline {y} length {b2 << 8 | b3} does not match width {width}"
                )
            line, pos = _decode_rle_line(buf, pos + 4, width, y, p)
            out[y] = np.frombuffer(line, np.uint8).reshape(4, width).T
            prev = out[y, -1].copy()
            continue
        # Flat scanline: one vectorised copy unless it holds old-style run markers (1, 1, 1, n).
        if pos + 4 * width <= size:
            px = arr[pos : pos + 4 * width].reshape(width, 4)
            if not np.any((px[:, 0] == 1) & (px[:, 1] == 1) & (px[:, 2] == 1)):
                out[y] = px
                pos += 4 * width
                prev = out[y, -1].copy()
                continue
        x = 0
        shift = 0
        while x < width:
            if pos + 4 > size:
                raise ValueError(f"'{p}': file truncated in scanline {y}")
            px = arr[pos : pos + 4]
            pos += 4
            if px[0] == 1 and px[1] == 1 and px[2] == 1:
                if prev is None:
                    raise ValueError(f"'{p}': old-style run with no previous pixel")
                count = int(px[3]) << shift
                if x + count > width:
                    raise ValueError(f"'{p}': old-style run overflows scanline {y}")
                out[y, x : x + count] = prev
                x += count
                shift += 8
            else:
                out[y, x] = px
                prev = out[y, x].copy()
                x += 1
                shift = 0
        prev = out[y, -1].copy()
    return out


def read_hdr_header(path) -> dict:
    """Header of a Radiance file: ``program``, ``format``, ``exposure`` (product of EXPOSURE
    lines, 1.0 if none), ``orientation`` (resolution line), ``width``, ``height``."""
    p = existing_file(path)
    with open(p, "rb") as fh:
        data = fh.read(_MAX_HEADER + 256)
    info, _ = _parse_header(data, p)
    h, w = _image_shape(info)
    return {k: info[k] for k in ("program", "format", "exposure", "orientation")} | {
        "width": w,
        "height": h,
    }


def _image_shape(info) -> tuple[int, int]:
    (a1, _), (n1, n2) = info["axes"], info["dims"]
    return (n1, n2) if a1[1] == "Y" else (n2, n1)


def read_hdr(path, *, offset: float = 0.5) -> np.ndarray:
    """Read a Radiance ``.hdr`` file as float32 RGB ``(H, W, 3)`` (top row first).

    ``offset``: decoding offset added to the 8-bit mantissas, 0.5 (Radiance, default) or 0.0
    (OpenCV / Walter's ``rgbe.c``; see the module docstring). Raises ``FileNotFoundError`` for a
    missing file, ``ValueError`` naming the file for a bad header, unsupported format, or
    truncated/corrupt pixel data.

    Example: the RGBE pixel ``(128, 64, 0, 129)`` decodes to ``(1.00390625, 0.50390625,
    0.00390625)`` with ``offset=0.5`` and to ``(1.0, 0.5, 0.0)`` with ``offset=0.0``.
    """
    p = existing_file(path)
    data = p.read_bytes()
    info, pos = _parse_header(data, p)
    n1, n2 = info["dims"]
    if n1 * n2 > 2**31:
        raise ValueError(f"'{p}': implausible image size {n1}x{n2}")
    raw = _decode_scanlines(data, pos, n1, n2, p)
    img = float_from_rgbe(raw, offset=offset)
    (s1, a1), (s2, _) = info["axes"]
    if a1 == "Y":  # rows are scanlines; '-Y' = top to bottom, '+X' = left to right
        if s1 == "+":
            img = img[::-1]
        if s2 == "-":
            img = img[:, ::-1]
    else:  # scanlines are columns
        img = img.transpose(1, 0, 2)  # now (Y, X)
        if s2 == "+":
            img = img[::-1]
        if s1 == "-":
            img = img[:, ::-1]
    return np.ascontiguousarray(img)


# ----------------------------------------------------------------------------- writing

_MINRUN = 4


def _chunks(starts: np.ndarray, lengths: np.ndarray, m: int):
    """Split spans ``(start, length)`` into consecutive chunks of at most ``m`` elements."""
    k = -(-lengths // m)
    span = np.repeat(np.arange(starts.size), k)
    j = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
    return starts[span] + m * j, np.minimum(m, lengths[span] - m * j)


def _rle_encode(planar: np.ndarray) -> bytes:
    """New-style RLE of scanlines ``planar`` ``(H, 4, W)`` uint8, vectorised over the image.

    Each component of each scanline is coded as runs of >= 4 equal bytes (``128 + n, value``,
    n <= 127) and literal chunks (``n, bytes...``, n <= 128), after a ``2 2 W_hi W_lo`` marker.
    """
    h, _, w = planar.shape
    flat = planar.reshape(-1)
    n = flat.size
    start = np.ones(n, bool)
    start[1:] = flat[1:] != flat[:-1]
    start[::w] = True  # runs never cross a component/scanline boundary
    rs = np.flatnonzero(start)
    rl = np.diff(np.append(rs, n))
    long = rl >= _MINRUN
    # literal spans: maximal groups of consecutive short runs within one component line
    lit = np.repeat(~long, rl)
    line_start = np.zeros(n, bool)
    line_start[::w] = True
    lit_start = lit.copy()
    lit_start[1:] &= ~lit[:-1] | line_start[1:]
    ls = np.flatnonzero(lit_start)
    lit_end = lit.copy()
    lit_end[:-1] &= ~lit[1:] | line_start[1:]
    ll = np.flatnonzero(lit_end) + 1 - ls
    run_s, run_l = _chunks(rs[long], rl[long], 127)
    lit_s, lit_l = _chunks(ls, ll, 128)
    cs = np.concatenate([run_s, lit_s])
    cl = np.concatenate([run_l, lit_l])
    is_run = np.concatenate([np.ones(run_s.size, bool), np.zeros(lit_s.size, bool)])
    order = np.argsort(cs, kind="stable")
    cs, cl, is_run = cs[order], cl[order], is_run[order]
    size = np.where(is_run, 2, 1 + cl)
    row = cs // (4 * w)
    pos = np.cumsum(size) - size + 4 * (row + 1)
    out = np.empty(int(size.sum()) + 4 * h, np.uint8)
    out[pos] = np.where(is_run, 128 + cl, cl)
    out[pos[is_run] + 1] = flat[cs[is_run]]
    # literal bytes keep their order: output index = source index + a per-chunk shift
    li = ~is_run
    src = np.flatnonzero(lit)
    out[src + np.repeat(pos[li] + 1 - cs[li], cl[li])] = flat[src]
    first = np.searchsorted(row, np.arange(h))
    marker = pos[first] - 4
    for i, v in enumerate((2, 2, w >> 8, w & 0xFF)):
        out[marker + i] = v
    return out.tobytes()


def write_hdr(path, image, *, rle: bool = True) -> None:
    """Write float RGB ``(H, W, 3)`` (or grey ``(H, W)``, replicated) as a Radiance ``.hdr``.

    Header ``#?RADIANCE`` / ``FORMAT=32-bit_rle_rgbe`` / ``-Y H +X W``; pixels encoded with
    :func:`rgbe_from_float`; scanlines new-style run-length encoded when ``rle`` and
    ``8 <= W <= 32767`` (as Radiance and OpenCV), flat otherwise.
    """
    p = output_path(path)
    arr = as_image_array(image)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=-1)
    if arr.shape[-1] != 3:
        raise ValueError(f"image: expected (H, W, 3) or (H, W), got shape {arr.shape}")
    h, w, _ = arr.shape
    rgbe = rgbe_from_float(arr)
    out = bytearray(b"#?RADIANCE\n# written by jaxgfx\nFORMAT=32-bit_rle_rgbe\n\n")
    out += f"-Y {h} +X {w}\n".encode()
    if rle and 8 <= w <= 0x7FFF:
        out += _rle_encode(np.ascontiguousarray(rgbe.transpose(0, 2, 1)))  # (H, 4, W)
    else:
        out += np.ascontiguousarray(rgbe).tobytes()
    p.write_bytes(bytes(out))
