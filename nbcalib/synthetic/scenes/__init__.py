"""The procedural scenes of :func:`nbcalib.synthetic.scene.make_scene`, one module per kind.

Each module has one entry point ``make_<kind>(config, rng)`` that builds the scene step by step
(:class:`~nbcalib.synthetic.builder.SceneBuilder`) from a generator seeded by ``make_scene``.
"""
