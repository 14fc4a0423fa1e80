"""numba kernels: private, array-in / array-out, called only through nbcalib's public wrappers.

Nothing here validates its input; the wrappers in :mod:`nbcalib.transforms`,
:mod:`nbcalib.camera` and the pipeline modules do. Slow, readable references of every kernel live
in :mod:`nbcalib.reference`, and the tests compare the two.
"""
