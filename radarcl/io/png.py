"""8-bit greyscale PNG images, as radar scans are stored: checked before decoding, and decoded
by hand where they are the kind radar writers produce.

``verify_png`` checks the signature and every chunk's CRC-32 (PIL stops reading once it has its
pixels, so a damaged final deflate block would otherwise decode into wrong pixels without a
word). ``greyscale_rows`` inflates an image whose rows are all filtered "None" or all "Sub" (a
"Sub" row holds each pixel's difference from the one before it, mod 256) and hands its rows on
as stored; ``running_sums`` undoes the "Sub" filter, and ``greyscale_pixels`` is the two. A scan
whose levels go to the device may travel as its differences: the device takes the running sums
itself (``stages.levels``), and the host only inflates.

By hand because a drive decodes a scan per frame beside the device's fusion on the same cores:
PIL inflates with zlib in small blocks and undoes the filters a row at a time, while ISA-L's
inflate (``isal``) and vectorised running sums over blocks of rows take a fraction of its time
for the same pixels. Any other PNG (other filters, depths, colours, interlacing) is left to PIL.
"""

from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PEEK_ROWS = 4                      # rows inflated to see a PNG's filters before the rest (greyscale_rows)
UNFILTER_BLOCK_BYTES = 2 ** 18     # pixels "Sub"-unfiltered at a time: within a core's level-2 cache


def verify_png(path, raw=None):
    """Check a PNG's signature and every chunk's CRC-32 before decoding: PIL stops reading the
    image data once it has its pixels, so a damaged final deflate block (whose Adler-32 it
    never reads) would otherwise decode into wrong pixels without a word (found by the fuzz
    suite). ``raw``: the file's bytes when already read. Returns the (width, height) of its IHDR."""
    import struct
    import zlib

    if raw is None:
        try:
            raw = Path(path).read_bytes()
        except OSError as exc:
            raise FrameFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if not raw.startswith(PNG_SIGNATURE):
        raise FrameFormatError(f"{path}: not a PNG file (no PNG signature)")
    i, size, ended = len(PNG_SIGNATURE), None, False
    while i + 12 <= len(raw) and not ended:
        length, kind = struct.unpack(">I4s", raw[i:i + 8])
        end = i + 12 + length
        if end > len(raw):
            break
        body = raw[i + 4:end - 4]
        if zlib.crc32(body) != struct.unpack(">I", raw[end - 4:end])[0]:
            raise FrameFormatError(f"{path}: PNG chunk {kind!r} at byte {i} fails its CRC: the file is damaged")
        if kind == b"IHDR":
            if size is not None or i != len(PNG_SIGNATURE) or length != 13:
                raise FrameFormatError(f"{path}: not a valid PNG (its header chunk IHDR must come first, once, of 13 "
                                       f"bytes; found one of {length} bytes at byte {i})")
            size = struct.unpack(">II", body[4:12])
            if 0 in size:
                raise FrameFormatError(f"{path}: not a valid PNG (it declares {size[0]} x {size[1]} pixels; the format "
                                       "has no empty images)")
        ended = kind == b"IEND"
        i = end
    if not ended or size is None:
        raise FrameFormatError(f"{path}: a truncated PNG (no IHDR or IEND chunk)")
    return size


def greyscale_rows(path, raw, width, height):
    """(rows, differenced) of a PNG that ``verify_png`` passed, when it is the kind radar scans
    are (8-bit greyscale, not interlaced, every row filtered "None" or every row "Sub"): its
    (height, width) uint8 rows as stored (a read-only view of the inflated bytes), ``differenced``
    True where they are "Sub" rows (``running_sums`` gives the pixels); None for any other PNG
    (PIL decodes those). A stream that inflates short, long or not at all is refused."""
    import struct

    from isal import isal_zlib

    i, header, parts = len(PNG_SIGNATURE), None, []
    while i + 12 <= len(raw):
        length, kind = struct.unpack(">I4s", raw[i:i + 8])
        if kind == b"IHDR":
            header = raw[i + 16:i + 21]                 # bit depth, colour type, compression, filter, interlace
        elif kind == b"IDAT":
            parts.append(raw[i + 8:i + 8 + length])
        elif kind == b"IEND":
            break
        i += 12 + length
    if header != bytes([8, 0, 0, 0, 0]) or not width or not height:
        return None
    expected = height * (width + 1)                     # a filter byte before each row
    data = b"".join(parts)
    try:
        # the first rows alone first: a PNG whose writer chose other filters goes to PIL uninflated;
        # then the whole image in one call (inflating on from the peek's state would copy the
        # stream's tail and the pixels once more)
        head = isal_zlib.decompressobj().decompress(data, min(PEEK_ROWS * (width + 1), expected))
        if not set(head[::width + 1]) <= {0, 1}:
            return None
        inflate = isal_zlib.decompressobj()
        out = inflate.decompress(data, expected + 1)    # bounded: a deflate bomb stops here
    except isal_zlib.error as exc:
        raise FrameFormatError(f"{path}: not a readable PNG (its image data do not inflate: {exc})") from exc
    size = f"the {expected} bytes of {height} x {width} pixels"
    if len(out) > expected:
        raise FrameFormatError(f"{path}: not a readable PNG (its image data inflate to more than {size})")
    if not inflate.eof:
        raise FrameFormatError(f"{path}: not a readable PNG (its image data stop after {len(out)} bytes, before "
                               f"their stream's end; expected {size})")
    if len(out) < expected:
        raise FrameFormatError(f"{path}: not a readable PNG (its image data inflate to {len(out)} bytes, "
                               f"expected {size})")
    rows = np.frombuffer(out, np.uint8).reshape(height, width + 1)
    filters = rows[:, 0]
    if (filters == 0).all():
        return rows[:, 1:], False
    if not (filters == 1).all():
        return None
    return rows[:, 1:], True


def running_sums(rows):
    """Undo PNG's "Sub" filter: a new (h, w) uint8 array whose row i holds the running sums,
    mod 256, of ``rows[i]`` (each pixel its difference from the one before it, the first its
    value).

    A block of rows at a time, by doubling steps (log2(w) vector adds over the block; numpy
    reads an overlapping operand before it writes): not a scalar recurrence along each row, and
    a block small enough that its passes stay in the core's cache."""
    height, width = rows.shape
    pixels = np.empty((height, width), np.uint8)
    block = max(1, UNFILTER_BLOCK_BYTES // max(width, 1))
    for top in range(0, height, block):
        filtered, band, step = rows[top:top + block], pixels[top:top + block], 2
        band[:, :1] = filtered[:, :1]
        np.add(filtered[:, 1:], filtered[:, :-1], out=band[:, 1:])     # the first step, from the filtered bytes
        while step < width:
            band[:, step:] += band[:, :-step]           # uint8: mod 256, as the filter's sum is
            step *= 2
    return pixels


def greyscale_pixels(path, raw, width, height):
    """The (height, width) uint8 pixels of a PNG that ``verify_png`` passed, when it is the kind
    ``greyscale_rows`` decodes; None for any other PNG (PIL decodes those)."""
    found = greyscale_rows(path, raw, width, height)
    if found is None:
        return None
    rows, differenced = found
    return running_sums(rows) if differenced else rows.copy()
