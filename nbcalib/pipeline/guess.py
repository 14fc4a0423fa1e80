"""The matching and initial-guess stages of a job (paper section III-D).

:class:`GuessSteps` is the part of :class:`~nbcalib.pipeline.Calibrator` that turns the
preprocessed pairs into a start for fine registration: keypoint matches per pair
(:mod:`nbcalib.matching`), then rotation-only RANSAC and robust LM over the pooled
correspondences (:mod:`nbcalib.initial_guess`), or hand-picked correspondences, or a fallback
pose when the automatic guess fails.
"""

from __future__ import annotations

import logging

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io.calib_json import AUTO_STAGE, MANUAL_STAGE
from nbcalib.io.job_record import GuessFigures
from nbcalib.pipeline.records import _detail, _rounded
from nbcalib.products import Start

__all__ = ["GuessSteps"]

log = logging.getLogger("nbcalib.pipeline")


class GuessSteps:
    """Matching and the initial guess of a :class:`~nbcalib.pipeline.Calibrator`."""

    def _use_fallback(self, exc: InputError) -> None:
        """The automatic guess failed: record it, and start from the fallback pose instead."""
        # the guess's own reason when there is one (the error adds what to do next)
        failed = self.guess is not None and not self.guess.success
        reason = self.guess.failure if failed else str(exc)
        log.warning(
            "automatic initial guess failed (%s): calibrating from %s instead",
            reason,
            self._fallback.source,
        )
        self._guess_failed = True
        self._forget_after("initial-guess")
        calib = self._calib()
        if calib is not None:
            calib.record.guess().failed = reason
        self._remember("initial-guess", calib)

    def _match(self) -> None:
        from nbcalib.matching.find import find_correspondences

        camera, cfg = self._camera(), self.config
        prior = self._prior.T_camera_lidar if self._prior is not None else None
        self.matches = {}
        pairs = self._pairs()
        if len(pairs) > 1 and cfg.matching.views > 0:
            # the frames of a recording share one extrinsic: they vote, then a few are matched
            self._match_recording(pairs, prior)
        else:  # one pair, or the stored LiDAR images as the reference toolbox matches them
            for k, pair in enumerate(pairs):
                if len(pairs) > 1:
                    log.info("    [%d/%d] %s", k + 1, len(pairs), pair.name)
                found = find_correspondences(
                    camera,
                    pair,
                    cfg.matching,
                    guess_config=cfg.initial_guess,
                    virtual_camera=self._virtual(),
                    T_camera_lidar_prior=prior,
                    seed=cfg.seed,
                    model_dir=self.model_dir,
                    progress=True,
                )
                _detail(found.summary())
                self.matches[pair.name] = found
                self.store.write_matches(found, pair, draw=cfg.matching.draw)
        self._forget_after("find-matches")
        self._remember("find-matches", self._calib())

    def _match_recording(self, pairs, prior) -> None:
        """Match the frames of a recording together (:mod:`nbcalib.matching.recording`)."""
        from dataclasses import replace

        from nbcalib.matching.find import unmatched_pair
        from nbcalib.matching.match import resolve_matcher
        from nbcalib.matching.recording import match_recording
        from nbcalib.progress import Progress

        cfg = self.config
        matching = replace(
            cfg.matching, matcher=resolve_matcher(cfg.matching.matcher, self.model_dir)
        )
        with Progress(label="find-matches") as display:

            def progress(what, done, total):
                display.total = total
                display.done = done - 1
                display.update(what=what)

            found = match_recording(
                self._camera(),
                pairs,
                matching,
                cfg.initial_guess,
                origin=self._lidar_origin(),
                T_camera_lidar_prior=prior,
                seed=cfg.seed,
                model_dir=self.model_dir,
                log_line=_detail,
                progress=progress,
            )
        for pair in pairs:
            if pair.name in found.found:
                matched = found.found[pair.name]
                draw = cfg.matching.draw
            else:
                reason = (
                    f"{len(found.agreeing)} matched frames already agree on the pose "
                    f"(matching.guess_pairs {cfg.matching.guess_pairs}: 0 matches every frame)"
                )
                matched, draw = unmatched_pair(pair, matching.matcher, reason), False
            self.matches[pair.name] = matched
            self.store.write_matches(matched, pair, draw=draw)
        self._recording = found

    def _initial_guess(self) -> None:
        from nbcalib.initial_guess.estimate import MIN_CORRESPONDENCES, estimate_initial_guess

        cfg = self.config.initial_guess
        corr, stage, where = self._guess_correspondences()
        manual = self._manual is not None
        if len(corr) < MIN_CORRESPONDENCES:
            hint = (
                "add more picks"
                if manual
                else "check the matches (nbcalib find-matches) or pick correspondences by hand "
                "with run.manual"
            )
            raise InputError(
                f"too few correspondences: {len(corr)} (need at least {MIN_CORRESPONDENCES}); "
                f"{hint}",
                where,
            )
        guess = estimate_initial_guess(
            self._camera(),
            corr.uv_camera,
            corr.points_lidar,
            cfg,
            seed=self.config.seed,
            weights=corr.weights if cfg.confidence_weights else None,
            min_inliers=cfg.min_manual_inliers if manual else cfg.min_inliers,
            # a few picks make wide bounds, without the shared error of learned matches
            precision_scale=0.0 if manual else cfg.precision_scale,
            origin=self._lidar_origin(),
        )
        self.guess, self._guess_corr = guess, corr
        _detail(guess.summary())
        matcher = None if manual else self._matcher_name()
        source = f"hand-picked correspondences ({self._manual})" if manual else f"{matcher} matches"
        # a guess whose matches found the pose is refined even when its precision is in doubt:
        # fine registration's basin is wider than the test's bound, and the report judges the end
        if not guess.found and not self._accept_failed_guess:
            if manual:
                raise InputError(
                    f"initial guess not written: {guess.failure} (run.force writes it anyway)",
                    where,
                )
            raise InputError(
                f"initial guess not written: {guess.failure}; the {source} found no pose the "
                "camera and the LiDAR agree on (see *_matches.png). Next: a rough extrinsic "
                "with run.init X,Y,Z,QX,QY,QZ,QW [run.init_uncertainty M DEG], hand-picked "
                "correspondences with run.manual FILE, or a rough orientation for matching with "
                "run.prior X,Y,Z,QX,QY,QZ,QW",
                where,
            )
        log.info(
            "    initial guess from %s: %d of %d correspondences agree (RMS %.2f px), %.1fx "
            "the best other rotation: %s",
            source,
            guess.n_inliers,
            guess.n_correspondences,
            guess.rms_px,
            guess.distinctiveness,
            "looks right"
            if guess.success
            else "imprecise: fine registration refines it and the report judges the result"
            if guess.found
            else "FAILED its test, kept as asked",
        )
        self.start = Start.from_matrix(guess.T_camera_lidar, stage)
        self._forget_after("initial-guess")
        calib = self._calib()
        if calib is not None:
            # the start's own seven numbers (values of the guess's matrix), so that a job
            # resumed from calib.json starts where this one starts, to the bit
            calib.set_T_camera_lidar(stage, guess.T_camera_lidar)
            calib.record.guess().stages[stage] = GuessFigures.make(
                correspondences=len(corr),
                ransac_inliers=guess.ransac.n_inliers,
                inliers=guess.n_inliers,
                rms_px=None if not np.isfinite(guess.rms_px) else round(guess.rms_px, 4),
                support=guess.support,
                runner_up=guess.runner_up,
                runner_up_shared=guess.runner_up_shared,
                bound_m=_rounded(guess.bound_m, 5),
                bound_deg=_rounded(guess.bound_deg, 4),
                success=bool(guess.success),
                seed=self.config.seed,
                confidence_weights=bool(cfg.confidence_weights and corr.confidence is not None),
                source=str(self._manual) if manual else "matches",
                matcher=matcher,
                precise=bool(guess.precise),
            )
        self._remember("initial-guess", calib)

    def _guess_correspondences(self):
        """(pooled correspondences, calib.json stage, path for messages) for the initial guess."""
        from nbcalib.matching.correspondences import pool_correspondences

        search_radius = self.config.matching.search_radius
        if self._manual is not None:
            from nbcalib.initial_guess.manual import (
                read_manual_correspondences,
                resolve_manual_correspondences,
            )

            entries = read_manual_correspondences(self._manual)
            corr = resolve_manual_correspondences(
                entries, self._pairs(), search_radius=search_radius, path=self._manual
            )
            _detail(f"{len(corr)} manual correspondences from {self._manual}")
            self._guess_parts = [corr]
            return corr, MANUAL_STAGE, self._manual
        parts = []
        for pair in self._pairs():
            if pair.name in self.matches:
                part = self.matches[pair.name].correspondences
            else:
                part = self.store.read_correspondences(pair, search_radius=search_radius)
            log.debug(
                "    %s: %d matches, %d 2D-3D correspondences", pair.name, part.n_matches, len(part)
            )
            parts.append(part)
        self._guess_parts = parts
        return pool_correspondences(parts), AUTO_STAGE, self.store.path

    def _matcher_name(self) -> str:
        """Which matcher made the correspondences ("xfeat-lighterglue"; "keypoint" if unknown)."""
        names = {m.matcher for m in self.matches.values()} if self.matches else set()
        if not names:  # matched by an earlier run: the kept correspondences say
            names = self.store.matcher_names(self._pairs())
        return " + ".join(sorted(names)) or "keypoint"

    def _lidar_origin(self):
        """Where the LiDAR sits in the clouds' frame: the virtual camera's position (or None)."""
        virtual = self._virtual()
        return None if virtual is None else virtual.origin
