"""Slow, readable references of nbcalib's kernels, one module per area.

Tests compare the kernels with them, and the notebooks teach from them.
"""
