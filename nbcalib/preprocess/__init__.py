"""Preprocessing: from raw scans and an image to a work directory (paper section III-C, III-D).

Modules (import them directly; this package imports nothing, so it stays cheap):

- :mod:`nbcalib.preprocess.intensity`: rank-based equalisation of point intensities and
  histogram equalisation of camera images (both optional).
- :mod:`nbcalib.preprocess.accumulate`: dense clouds from many scans of a LiDAR at rest (voxel
  de-duplication), and the :class:`~nbcalib.preprocess.accumulate.DenseCloud` result; a moving
  LiDAR's scans are registered and deskewed by :mod:`nbcalib.odometry` (continuous-time ICP).
- :mod:`nbcalib.preprocess.lidar_image`: the LiDAR field of view, the virtual camera, z-buffer
  rendering of the intensity image and the index map, and hidden-point removal.
- :mod:`nbcalib.workdir`: reading and writing the work directory shared with the
  reference toolbox (``<name>.png``, ``<name>.ply``, ``<name>_lidar_intensities.png``,
  ``<name>_lidar_indices.png``, ``calib.json``).
"""
