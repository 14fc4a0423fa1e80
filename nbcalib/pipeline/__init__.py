"""The calibration pipeline: one job, stage by stage, in the order of the paper's method section.

:class:`Calibrator` is the only orchestrator: ``nbcalib run``, ``nbcalib demo``, every stage
command (``nbcalib preprocess``, ``find-matches``, ``initial-guess``, ``calibrate``,
``report``) and :func:`nbcalib.calibrate` are thin shells over it, so a job gives the same
result whichever door it comes in by. Its :meth:`~Calibrator.run` reads like the method::

    preprocess    III-C  scans -> dense cloud per pair; equalised intensities and image
    render        III-D  a virtual camera renders each cloud: LiDAR intensity image + index map
    match         III-D  camera image x camera-shaped LiDAR views -> 2D-3D correspondences
    initial guess III-D  rotation-only RANSAC + Cauchy-robust LM -> initial T_camera_lidar
    refine        III-E  hidden-point removal + NID minimisation over all pairs -> T_camera_lidar
    assess               NID curves, uncertainty and a verdict (the quality report)

Each step hands a typed product to the next (:mod:`nbcalib.products`). With a work directory
(:mod:`nbcalib.workdir`) every product is also saved, with a record of what made it (the config
sections and inputs it used); a later run keeps each product whose record matches, and redoes
the rest and everything after it. Without one the job runs in memory. Both compute the same
numbers: products are exactly what the files hold (:mod:`nbcalib.products`).

The package's rooms: :mod:`~nbcalib.pipeline.calibrator` (the job: its stages in order and its
products), :mod:`~nbcalib.pipeline.guess` (the matching and initial-guess stages) and
:mod:`~nbcalib.pipeline.records` (what made each product, where fine registration starts).

Example
-------
>>> from nbcalib.pipeline import Calibrator
>>> from nbcalib.preprocess.inputs import InputSpec
>>> spec = InputSpec(inputs=("scan.pcd", "image.png"), camera="camera.yaml")  # doctest: +SKIP
>>> result = Calibrator(workdir="work").run(spec)                             # doctest: +SKIP
>>> result.T_lidar_camera, result.quality.verdict                             # doctest: +SKIP
"""

from nbcalib.pipeline.calibrator import Calibrator, make_report
from nbcalib.resume import STAGES

__all__ = ["STAGES", "Calibrator", "make_report"]
