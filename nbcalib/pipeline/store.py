"""Where a job keeps its products: one interface, in memory for the API, on disk for the CLI.

The :class:`~nbcalib.pipeline.Calibrator` holds each product it makes (the pairs, the matches,
the guess, the result, the quality) as attributes, and hands it to its store, which keeps what
it can: :class:`WorkDirStore` writes the work directory (:class:`~nbcalib.workdir.WorkDir`: the
pairs' files, ``calib.json`` with the records of what made each product, the matches, the
report), so that a later run resumes from it; :class:`MemoryStore` keeps nothing beyond the
Calibrator's own attributes (no file, no record: :meth:`MemoryStore.read_calib` is None). The
Calibrator asks the store, never which kind of store it has.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

from nbcalib.config import write_config
from nbcalib.errors import InputError
from nbcalib.workdir import WorkDir

__all__ = ["MemoryStore", "WorkDirStore", "make_store"]


class MemoryStore:
    """The products of an in-memory job: the Calibrator's attributes, nothing more.

    Writing is a no-op, nothing is read back, and there are no records (``read_calib`` is
    None), so every stage runs on what this job made.
    """

    work = None
    path = None
    calib_path = None

    def __repr__(self) -> str:
        return "MemoryStore()"

    def check_writable(self) -> None:
        """Refuse a place where products cannot be written (InputError naming it)."""

    def lock(self):
        """Nothing to lock in memory: a context that does nothing."""
        return contextlib.nullcontext()

    def prepare(self) -> None:
        """Make room for a new preprocessing run, removing what it makes stale."""

    def commit(self) -> None:
        """A preprocessing run is complete (nothing to move in memory)."""

    def abort(self) -> None:
        """A preprocessing run failed (nothing to remove in memory)."""

    def read_calib(self):
        """The job's records and results (``calib.json``); None when none are kept."""
        return None

    def is_complete(self) -> bool:
        """The store holds a finished preprocessing run (every pair's products)."""
        return False

    def write_calib(self, calib) -> None:
        """Keep the job's records and results (written last: it marks the job done)."""

    def write_config(self, config, extra: dict) -> None:
        """Keep the settings used, for a later run to start from."""

    def require_preprocessed(self):
        """The records of a preprocessed job, else an InputError saying why."""
        raise InputError("nothing is preprocessed in this job: run its preprocess stage first")

    def load_pairs(self, *, budget=None) -> list:
        """The preprocessed pairs kept by an earlier run."""
        return self.require_preprocessed()

    def write_pair(self, pair, budget=None):
        """Keep one preprocessed pair; returns it as the job goes on with it (here: itself)."""
        return pair

    def write_matches(self, found, pair, *, draw: bool) -> None:
        """Keep one pair's matches and correspondences (and their picture)."""

    def read_correspondences(self, pair, *, search_radius: float):
        """One pair's 2D-3D correspondences kept by an earlier run."""
        raise InputError(f"{pair.name}: no matches in this job: run its find-matches stage first")

    def matcher_names(self, pairs) -> set[str]:
        """The matchers that made the kept correspondences of ``pairs``."""
        return set()

    def remove_derived(self) -> None:
        """Remove the report and exports of a result that is about to change."""

    def write_report(self, *args, **kwargs):
        """No report without a folder to write it to: None (the quality is the product)."""
        return None


class WorkDirStore:
    """The products of a job in its work directory (:class:`~nbcalib.workdir.WorkDir`)."""

    #: Where a rerun of preprocessing writes, inside the work directory, until it is complete.
    STAGING = ".nbcalib-preprocess"

    def __init__(self, work: WorkDir):
        self.work = work
        self._final: WorkDir | None = None  # the work directory while a rerun is staged

    def __repr__(self) -> str:
        return f"WorkDirStore({str(self.work.path)!r})"

    @property
    def path(self) -> Path:
        """The work directory."""
        return (self._final or self.work).path

    @property
    def calib_path(self) -> Path:
        """``calib.json``, the file errors about the job's records name."""
        return self.work.calib_path

    def check_writable(self) -> None:
        """Refuse a place where products cannot be written (InputError naming it)."""
        self.work.check_writable()

    def lock(self):
        """Hold the work directory's lock: one job at a time (:mod:`nbcalib.io.workdir_lock`)."""
        from nbcalib.io.workdir_lock import workdir_lock

        return workdir_lock(self.path)

    def prepare(self) -> None:
        """Make room for a new preprocessing run.

        In a new work directory the run writes in place. Over a job that has records (a rerun,
        ``--force``) it writes into :attr:`STAGING` inside it, so that a run that fails (a full
        disk, an interrupt, bad input found late) leaves the job, its result and its report
        as they were; :meth:`commit` then puts the new products in place, :meth:`abort`
        removes them.
        """
        if self._final is not None:
            self.abort()
        if not self.work.calib_path.is_file():
            self.work.prepare()
            return
        import shutil

        staging = WorkDir(self.work.path / self.STAGING)
        shutil.rmtree(staging.path, ignore_errors=True)
        staging.prepare()
        self._final, self.work = self.work, staging

    def commit(self) -> None:
        """A staged preprocessing run replaces the job it reran (``calib.json`` last).

        The old ``calib.json`` goes first: should the moves stop half-way, no result stands
        beside products it was not computed from. Moves within one file system take no room.
        """
        if self._final is None:
            return
        import os

        staging, final = self.work, self._final
        final.calib_path.unlink(missing_ok=True)
        final.remove_derived()
        for name in staging.names():
            for stale in final.match_paths(name):  # matches of the old LiDAR image
                stale.unlink(missing_ok=True)
        for path in sorted(staging.path.iterdir()):
            if path.name != staging.calib_path.name:
                os.replace(path, final.path / path.name)
        os.replace(staging.calib_path, final.calib_path)
        staging.path.rmdir()
        self.work, self._final = final, None

    def abort(self) -> None:
        """Remove a staged preprocessing run that did not finish; the job is as it was."""
        if self._final is None:
            return
        import shutil

        shutil.rmtree(self.work.path, ignore_errors=True)
        self.work, self._final = self._final, None

    def read_calib(self):
        """The job's records and results (``calib.json``); None when none are kept."""
        return self.work.read_calib()

    def is_complete(self) -> bool:
        """The store holds a finished preprocessing run (every pair's products)."""
        return self.work.is_complete()

    def write_calib(self, calib) -> None:
        """Keep the job's records and results (written last: it marks the job done)."""
        self.work.write_calib(calib)

    def write_config(self, config, extra: dict) -> None:
        """The settings used (``nbcalib_config.yaml``), for ``nbcalib run --config``."""
        write_config(self.work.config_path, config, extra)

    def require_preprocessed(self):
        """The records of a preprocessed job, else an InputError saying why."""
        return self.work.require_preprocessed()

    def load_pairs(self, *, budget=None) -> list:
        """The preprocessed pairs kept by an earlier run.

        Their clouds are read when needed and kept in ``budget``
        (:class:`~nbcalib.clouds.MemoryBudget`) as it allows.
        """
        self.work.require_preprocessed()
        return self.work.load_pairs(budget=budget)

    def write_pair(self, pair, budget=None):
        """Keep one preprocessed pair (image, cloud, LiDAR image, index map).

        Returns the pair as the job goes on with it: its cloud now read from the PLY just
        written when needed (the same float32 values), kept in ``budget`` as it allows, and its
        LiDAR image read when asked for, so that a job's memory does not grow with its pairs.
        """
        from dataclasses import replace

        from nbcalib.clouds import Cloud

        self.work.write_pair(pair)
        if budget is None:
            return pair
        from nbcalib.workdir import StoredLidarImage

        # where the files will be once the run is complete (staged: after commit)
        work = self._final or self.work
        cloud = Cloud(path=work.cloud_path(pair.name), size=len(pair), budget=budget)
        return replace(pair, cloud=cloud, lidar_image=StoredLidarImage(work, pair.name))

    def write_matches(self, found, pair, *, draw: bool) -> None:
        """Keep one pair's matches and correspondences (and their picture)."""
        self.work.write_matches(found, pair, draw=draw)

    def read_correspondences(self, pair, *, search_radius: float):
        """One pair's 2D-3D correspondences kept by an earlier run."""
        return self.work.read_correspondences(pair, search_radius=search_radius)

    def matcher_names(self, pairs) -> set[str]:
        """The matchers the stored correspondences of ``pairs`` name (unreadable ones skipped)."""
        names = set()
        for pair in pairs:
            try:
                doc = json.loads(self.work.correspondences_path(pair.name).read_text())
            except (OSError, ValueError):
                continue
            if isinstance(doc, dict) and isinstance(doc.get("matcher"), str):
                names.add(doc["matcher"])
        return names

    def remove_derived(self) -> None:
        """Remove the report and exports of a result that is about to change."""
        self.work.remove_derived()

    def write_report(self, *args, **kwargs):
        """``report/index.html`` and its figures (:func:`nbcalib.report.html.write_report`)."""
        from nbcalib.report.html import write_report

        return write_report(self.work, *args, **kwargs)


def make_store(workdir=None) -> MemoryStore | WorkDirStore:
    """The store of a job: in memory (``workdir`` None), else its work directory."""
    if workdir is None:
        return MemoryStore()
    return WorkDirStore(workdir if isinstance(workdir, WorkDir) else WorkDir(workdir))
