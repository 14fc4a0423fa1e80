"""The procedural scenes, one module per kind, and :func:`make_scene`, which picks one.

Each module has one entry point ``make_<kind>(config, rng)`` that builds the scene step by step
(:class:`~nbcalib.synthetic.builder.SceneBuilder`) from a generator seeded by
:func:`make_scene`. What a scene is (:class:`~nbcalib.synthetic.scene.Scene`) lives below, in
:mod:`nbcalib.synthetic.scene`, which imports no generator.
"""

from __future__ import annotations

import numpy as np

from nbcalib.synthetic.scene import Scene, SceneConfig
from nbcalib.synthetic.scenes import room, street

__all__ = ["make_scene"]


def make_scene(config: SceneConfig | None = None, **overrides) -> Scene:
    """Generate a room or a street from a seed.

    Parameters
    ----------
    config : SceneConfig, optional
        Kind, seed, modality gap, texture switches; keyword overrides replace its fields
        (``make_scene(kind="street", seed=3)``).

    Returns
    -------
    Scene
    """
    config = SceneConfig(**{**(config.__dict__ if config else {}), **overrides})
    rng = np.random.default_rng([config.seed, 0x5CE7E])
    make = room.make_room if config.kind == "room" else street.make_street
    return make(config, rng)
