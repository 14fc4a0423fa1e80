"""Switches that turn single camera/LiDAR differences of the synthetic rig off (``--without``).

The synthetic camera and LiDAR see one scene in several physically different ways (the
*modality gap*); each name of :data:`EFFECTS` turns one of them off on its own, so that a
benchmark can measure what each one costs a calibration. They are listed in
``RigConfig.without`` (:class:`nbcalib.synthetic.rig.RigConfig`), ``nbcalib synth --without``
and ``ground_truth.json`` (``"without"``); the empty list, the default, is the rig as it always
was, bit for bit (every default computation is the one it was). Where each switch acts:

- the texture (``camera-texture``, ``lidar-texture``, ``materials``, ``elements``,
  :data:`TEXTURE_EFFECTS`): carried by the scene (``SceneConfig.without``, ``Scene.without``) and
  passed to the kernels as the bit mask ``off`` (:func:`nbcalib.synthetic.texture.texture_bits`;
  the formulas are in :mod:`nbcalib.kernels.synthetic_texture`);
- the camera (``shading``, ``shadows``, ``optics``): fields of the render configuration
  (:func:`render_without`);
- the LiDAR (``lidar-noise``, ``lidar-falloff``): fields of the LiDAR configuration
  (:func:`lidar_without`), recorded as such in each pair's ``lidar_config``;
- ``motion``: what is written (:meth:`nbcalib.synthetic.rig.SyntheticSequence.output_scans`):
  the simulation is the same, but each pair's points are written as one cloud already deskewed
  with the true trajectory.

How they compose with the modality gap ``g`` (``--modality-gap``): the LiDAR reflectivity is
``(1 - g) luminance(albedo) + g designed``. ``lidar-texture``, ``materials`` and ``elements``
change only the designed term, so they act in proportion to ``g`` and do nothing at ``g = 0``
(where the LiDAR already sees the camera's albedo luminance, camera texture included);
``camera-texture`` changes the albedo, so it acts on the camera and, through the ``1 - g``
term, on the LiDAR. With ``g = 1`` and all four, the LiDAR reflectivity is
``min(1, luminance(lerp(A, B, m)) (1 + v))`` and the camera albedo ``clip(lerp(A, B, m)
(1 + v), 0, 1)`` per channel: the same up to the clipping of single channels. The other switches
do not depend on ``g``.

This module imports nothing heavy: the command line reads it to build ``--help``.
"""

from __future__ import annotations

from dataclasses import replace

__all__ = [
    "DESCRIPTIONS",
    "EFFECTS",
    "LIDAR_EFFECTS",
    "RENDER_EFFECTS",
    "TEXTURE_EFFECTS",
    "check_effects",
    "lidar_without",
    "render_without",
]

#: What each switch turns off, one line each (``nbcalib synth --help``).
DESCRIPTIONS = {
    "shading": "camera radiance = albedo x a constant: no normals, sun angle, lamps or shadows",
    "shadows": "no cast shadows in the camera image (shading kept)",
    "camera-texture": "no camera-only texture (the camera's fBm stains)",
    "lidar-texture": "no LiDAR-only texture (the LiDAR's fBm paint and wetness)",
    "materials": "LiDAR reflectivity = camera colours' luminance: no inversions, glass, retro",
    "elements": "per-element tone (brick to brick) reaches the LiDAR in full, as the camera",
    "optics": "no optical blur, no read or shot noise in the image",
    "lidar-noise": "no range or intensity noise, no random dropouts, no beam footprint",
    "lidar-falloff": "LiDAR intensity independent of incidence angle and range",
    "motion": "points written deskewed with the true trajectory: one cloud per pair at t = 0",
}

#: Names of the differences that can be switched off, in a fixed order.
EFFECTS = tuple(DESCRIPTIONS)

#: The switches that act on the texture (the scene's materials as each sensor sees them).
TEXTURE_EFFECTS = ("camera-texture", "lidar-texture", "materials", "elements")
#: The switches that act on the camera image (:class:`~nbcalib.synthetic.render.RenderConfig`).
RENDER_EFFECTS = ("shading", "shadows", "optics")
#: The switches that act on the LiDAR returns (:class:`~nbcalib.synthetic.lidar.LidarConfig`).
LIDAR_EFFECTS = ("lidar-noise", "lidar-falloff")


def check_effects(without, allowed=EFFECTS) -> tuple[str, ...]:
    """``without`` validated and in the order of :data:`EFFECTS`, each name once.

    Parameters
    ----------
    without : iterable of str, str or None
        Effect names; a string is a comma-separated list (``"shading,optics"``); blanks around
        names and empty names are ignored; None is none.
    allowed : tuple of str
        The names accepted here (:data:`EFFECTS` or one of its groups).

    Returns
    -------
    tuple of str

    Raises
    ------
    ValueError
        For a name not in ``allowed``; the message names the valid ones.
    """
    if without is None:
        without = ()
    elif isinstance(without, str):
        without = without.split(",")
    names = {str(name).strip() for name in without} - {""}
    unknown = sorted(names - set(allowed))
    if unknown:
        raise ValueError(
            f"unknown effect{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
            f"expected some of {', '.join(allowed)}"
        )
    return tuple(name for name in EFFECTS if name in names)


def render_without(render, without):
    """A :class:`~nbcalib.synthetic.render.RenderConfig` with the camera switches applied.

    ``shading``: ``shading=False`` (radiance = albedo x ``ambient + sun_irradiance``; no shadow
    rays are needed then); ``shadows``: ``shadows=False``; ``optics``: ``blur_sigma_px``,
    ``read_noise`` and ``shot_noise`` 0 (the image is still exposed, gamma-encoded and quantised
    to 8 bits). ``render`` itself when none applies.
    """
    changes = {}
    if "shading" in without:
        changes["shading"] = False
    if "shadows" in without:
        changes["shadows"] = False
    if "optics" in without:
        changes.update(blur_sigma_px=0.0, read_noise=0.0, shot_noise=0.0)
    return replace(render, **changes) if changes else render


def lidar_without(lidar, without):
    """A :class:`~nbcalib.synthetic.lidar.LidarConfig` with the LiDAR switches applied.

    ``lidar-noise``: ``range_noise``, ``intensity_noise``, ``dropout`` and ``beam_divergence`` 0
    (the noise is still drawn, times 0, so the other draws stay as they were; glass dropouts are
    the material's, switched by ``materials``). ``lidar-falloff``: ``incidence_exponent`` and
    ``range_exponent`` 0, so the signal (and the intensity before its noise) is the reflectivity
    itself; the ``min_signal`` losses that came from incidence and range go with them, returns
    from surfaces whose reflectivity itself is below ``min_signal`` stay lost, and so do returns
    at grazing incidence (``cos <= 0.02``: no range to measure). ``lidar`` itself when none
    applies.
    """
    changes = {}
    if "lidar-noise" in without:
        changes.update(range_noise=0.0, intensity_noise=0.0, dropout=0.0, beam_divergence=0.0)
    if "lidar-falloff" in without:
        changes.update(incidence_exponent=0.0, range_exponent=0.0)
    return replace(lidar, **changes) if changes else lidar
