"""Slow, readable pure-Python LZF, the reference for :mod:`nbcalib.kernels.lzf`.

The stream format is described in :mod:`nbcalib.kernels.lzf`. :func:`lzf_compress` makes the same
greedy choices as the kernel (same hash, same table updates), so the two produce identical bytes.
"""

from __future__ import annotations

from nbcalib.kernels.lzf import HASH_LOG, MAX_LITERAL, MAX_MATCH, MAX_OFFSET


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decode an LZF stream that holds exactly ``size`` bytes.

    Parameters
    ----------
    data : bytes
        The compressed stream.
    size : int
        The number of bytes it decodes to.

    Returns
    -------
    bytes
        The decoded bytes, of length ``size``.

    Raises
    ------
    ValueError
        If the stream is truncated, refers before the start of the output, or does not decode to
        exactly ``size`` bytes.
    """
    out = bytearray()
    ip = 0
    while ip < len(data):
        ctrl = data[ip]
        ip += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            literal = data[ip : ip + ctrl + 1]
            if len(literal) != ctrl + 1:
                raise ValueError("LZF stream ends inside a literal run")
            out += literal
            ip += ctrl + 1
            continue
        length = ctrl >> 5  # back reference
        if length == 7:
            if ip >= len(data):
                raise ValueError("LZF stream ends inside a back reference")
            length += data[ip]
            ip += 1
        if ip >= len(data):
            raise ValueError("LZF stream ends inside a back reference")
        start = len(out) - ((ctrl & 31) << 8) - data[ip] - 1
        ip += 1
        if start < 0:
            raise ValueError("LZF back reference points before the start of the output")
        for k in range(length + 2):  # byte by byte: the copy may overlap its own output
            out.append(out[start + k])
        if len(out) > size:
            raise ValueError(f"LZF stream decodes to more than {size} bytes")
    if len(out) != size:
        raise ValueError(f"LZF stream decodes to {len(out)} bytes, expected {size}")
    return bytes(out)


def _hash(b0: int, b1: int, b2: int) -> int:
    return ((((b0 << 16) | (b1 << 8) | b2) * 2654435761) & 0xFFFFFFFF) >> (32 - HASH_LOG)


def lzf_compress(data: bytes) -> bytes:
    """Encode ``data`` as an LZF stream (greedy matching, as the kernel).

    Parameters
    ----------
    data : bytes
        The bytes to compress.

    Returns
    -------
    bytes
        The LZF stream; :func:`lzf_decompress` restores ``data`` from it.
    """
    n = len(data)
    last_seen: dict[int, int] = {}  # hash of a 3-byte prefix -> its latest position
    out = bytearray()
    literal = bytearray()

    def flush_literal():
        # a literal run is its length - 1, then the bytes
        out.append(len(literal) - 1)
        out.extend(literal)
        literal.clear()

    ip = 0
    while ip < n:
        if ip + 2 >= n:  # too close to the end for a 3-byte match
            literal.append(data[ip])
            ip += 1
        else:
            h = _hash(data[ip], data[ip + 1], data[ip + 2])
            ref = last_seen.get(h, -1)
            last_seen[h] = ip
            offset = ip - ref - 1
            if ref >= 0 and offset < MAX_OFFSET and data[ref : ref + 3] == data[ip : ip + 3]:
                length = 3
                while length < min(n - ip, MAX_MATCH) and data[ref + length] == data[ip + length]:
                    length += 1
                if literal:
                    flush_literal()
                code = length - 2
                if code < 7:
                    out.append((offset >> 8) + (code << 5))
                else:
                    out.extend([(offset >> 8) + (7 << 5), code - 7])
                out.append(offset & 255)
                for k in range(ip + 1, min(ip + length, n - 2)):
                    last_seen[_hash(data[k], data[k + 1], data[k + 2])] = k
                ip += length
            else:
                literal.append(data[ip])
                ip += 1
        if len(literal) == MAX_LITERAL:
            flush_literal()
    if literal:
        flush_literal()
    return bytes(out)
