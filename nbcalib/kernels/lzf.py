"""LZF compression, the codec of PCD ``DATA binary_compressed`` (liblzf by Marc Lehmann, as in PCL).

An LZF stream is a sequence of runs, each introduced by one control byte ``c``:

- ``c < 32``: a *literal run*; the next ``c + 1`` bytes are copied to the output.
- ``c >= 32``: a *back reference*; ``length = c >> 5`` (if it is 7, the next byte is added to it),
  then ``offset = ((c & 31) << 8) + next byte``; copy ``length + 2`` bytes starting
  ``offset + 1`` bytes before the current end of the output. Source and destination may overlap
  (a run of one repeated byte is a back reference with offset 0), so the copy goes byte by byte.

The longest back reference is 7 + 255 + 2 = 264 bytes and the farthest reaches 8192 bytes back.

The public wrappers are :func:`nbcalib.io.pcd.lzf_decompress` and
:func:`nbcalib.io.pcd.lzf_compress`; the slow, readable references are in
:mod:`nbcalib.reference.lzf`, and the compressor here emits exactly the reference's stream.
"""

from __future__ import annotations

import numpy as np

from nbcalib.kernels._jit import jit

MAX_LITERAL = 32  # longest literal run
MAX_OFFSET = 8192  # farthest back reference (13-bit offset + 1)
MAX_MATCH = 264  # longest back reference: 7 + 255 + 2 bytes
HASH_LOG = 14  # the compressor's hash table has 2**HASH_LOG entries

#: Error codes returned by :func:`_lzf_decompress` instead of a byte count.
ERR_OUTPUT_FULL = -1  # the stream decodes to more bytes than the output holds
ERR_BAD_REFERENCE = -2  # a back reference points before the start of the output
ERR_TRUNCATED = -3  # the stream ends inside a run


@jit
def _lzf_decompress(src, dst):
    """Decode the LZF stream ``src`` (uint8) into ``dst`` (uint8).

    Returns the number of bytes written, or a negative ``ERR_*`` code.
    """
    n_in = src.shape[0]
    n_out = dst.shape[0]
    ip = 0
    op = 0
    while ip < n_in:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:
            length = ctrl + 1
            if ip + length > n_in:
                return ERR_TRUNCATED
            if op + length > n_out:
                return ERR_OUTPUT_FULL
            for k in range(length):
                dst[op + k] = src[ip + k]
            ip += length
            op += length
        else:
            length = ctrl >> 5
            if length == 7:
                if ip >= n_in:
                    return ERR_TRUNCATED
                length += np.int64(src[ip])
                ip += 1
            if ip >= n_in:
                return ERR_TRUNCATED
            ref = op - ((ctrl & 31) << 8) - np.int64(src[ip]) - 1
            ip += 1
            length += 2
            if ref < 0:
                return ERR_BAD_REFERENCE
            if op + length > n_out:
                return ERR_OUTPUT_FULL
            for k in range(length):  # byte by byte: source and destination may overlap
                dst[op + k] = dst[ref + k]
            op += length
    return op


@jit
def _lzf_hash(b0, b1, b2):
    """Hash of three bytes into ``[0, 2**HASH_LOG)`` (Knuth's multiplicative hash)."""
    v = (np.int64(b0) << 16) | (np.int64(b1) << 8) | np.int64(b2)
    return ((v * 2654435761) & 0xFFFFFFFF) >> (32 - HASH_LOG)


@jit
def _lzf_compress(src, dst):
    """Encode ``src`` (uint8) as an LZF stream into ``dst`` (uint8).

    ``dst`` must hold ``len(src) + len(src) // 32 + 2`` bytes (the incompressible worst case).
    Greedy matching through a hash table of the last position of every 3-byte prefix, like liblzf.
    Returns the number of bytes written.
    """
    n = src.shape[0]
    table = np.full(1 << HASH_LOG, -1, dtype=np.int64)
    ip = 0
    op = 1  # dst[0] is the control byte of the first literal run
    lit_pos = 0
    lit = 0
    while ip + 2 < n:
        h = _lzf_hash(src[ip], src[ip + 1], src[ip + 2])
        ref = table[h]
        table[h] = ip
        off = ip - ref - 1
        if (
            ref >= 0
            and off < MAX_OFFSET
            and src[ref] == src[ip]
            and src[ref + 1] == src[ip + 1]
            and src[ref + 2] == src[ip + 2]
        ):
            max_len = min(n - ip, MAX_MATCH)
            length = 3
            while length < max_len and src[ref + length] == src[ip + length]:
                length += 1
            # close the pending literal run (or drop its unused control byte)
            if lit > 0:
                dst[lit_pos] = lit - 1
            else:
                op -= 1
            code = length - 2
            if code < 7:
                dst[op] = (off >> 8) + (code << 5)
                op += 1
            else:
                dst[op] = (off >> 8) + (7 << 5)
                dst[op + 1] = code - 7
                op += 2
            dst[op] = off & 255
            op += 1
            # index the positions inside the match so later data can refer to them
            for k in range(ip + 1, min(ip + length, n - 2)):
                table[_lzf_hash(src[k], src[k + 1], src[k + 2])] = k
            ip += length
            lit_pos = op
            op += 1
            lit = 0
        else:
            dst[op] = src[ip]
            op += 1
            ip += 1
            lit += 1
            if lit == MAX_LITERAL:
                dst[lit_pos] = lit - 1
                lit_pos = op
                op += 1
                lit = 0
    while ip < n:
        dst[op] = src[ip]
        op += 1
        ip += 1
        lit += 1
        if lit == MAX_LITERAL:
            dst[lit_pos] = lit - 1
            lit_pos = op
            op += 1
            lit = 0
    if lit > 0:
        dst[lit_pos] = lit - 1
    else:
        op -= 1
    return op
