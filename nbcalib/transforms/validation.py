"""Input checks of :mod:`nbcalib.transforms`: shapes, finiteness, rotations, rigid transforms.

Every public function of the package validates its arguments with the private helpers here;
:func:`validate_rotation`, :func:`validate_T` and :func:`is_valid_T` are the public checks.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["DEFAULT_ATOL", "FloatArray", "is_valid_T", "validate_T", "validate_rotation"]

FloatArray = NDArray[np.float64]

#: Tolerance of the rigidity checks: max |R^T R - I|, |det R - 1| and the last row of ``T``.
DEFAULT_ATOL = 1e-6

_EYE3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def _float_array(x: ArrayLike, name: str) -> FloatArray:
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers, got {type(x).__name__}") from exc


def _batch_arg(
    x: ArrayLike, name: str, shape: tuple[int, ...], *, batch: bool = True
) -> tuple[FloatArray, bool]:
    """``x`` as a C-contiguous float64 array of shape (N, *shape), and whether it was one item."""
    a = _float_array(x, name)
    single = a.shape == shape
    if not single and not (batch and a.ndim == len(shape) + 1 and a.shape[1:] == shape):
        expected = str(shape)
        if batch:
            expected += f" or (N, {', '.join(str(n) for n in shape)})"
        raise ValueError(f"{name} must have shape {expected}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite, but it holds NaN or inf")
    return np.ascontiguousarray(a.reshape((-1, *shape))), single


def _check_rotations(R: FloatArray, name: str, atol: float, single: bool) -> None:
    """Raise ValueError unless every R[n] of (N, 3, 3) is a rotation within ``atol``."""
    ortho = np.abs(np.swapaxes(R, 1, 2) @ R - _EYE3).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((ortho > atol) | (np.abs(det - 1.0) > atol))
    if bad.size:
        k = bad[0]
        item = "" if single else f" (item {k})"
        raise ValueError(
            f"{name} is not a rotation matrix{item}: max|R^T R - I| = {ortho[k]:.2e}, "
            f"det = {det[k]:.6f} (tolerance {atol:g})"
        )


def _check_transforms(T: FloatArray, name: str, atol: float, single: bool) -> None:
    """Raise ValueError unless every T[n] of (N, 4, 4) is a rigid transform within ``atol``."""
    row = np.abs(T[:, 3, :] - _LAST_ROW).max(axis=1)
    bad = np.flatnonzero(row > atol)
    if bad.size:
        k = bad[0]
        item = "" if single else f" (item {k})"
        raise ValueError(f"{name} must have last row [0, 0, 0, 1]{item}, got {T[k, 3].tolist()}")
    _check_rotations(T[:, :3, :3], f"{name}[:3, :3]", atol, single)


def _rotation_arg(R: ArrayLike, name: str, *, batch: bool = True) -> tuple[FloatArray, bool]:
    R, single = _batch_arg(R, name, (3, 3), batch=batch)
    _check_rotations(R, name, DEFAULT_ATOL, single)
    return R, single


def _transform_arg(T: ArrayLike, name: str, *, batch: bool = True) -> tuple[FloatArray, bool]:
    T, single = _batch_arg(T, name, (4, 4), batch=batch)
    _check_transforms(T, name, DEFAULT_ATOL, single)
    return T, single


def _fractions(s: ArrayLike) -> tuple[FloatArray, bool]:
    """Interpolation fractions as (N,), and whether ``s`` was a scalar."""
    a = _float_array(s, "s")
    if a.ndim > 1:
        raise ValueError(f"s must be a scalar or have shape (N,), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("s must be finite, but it holds NaN or inf")
    return a.reshape(-1), a.ndim == 0


def _unbatch(x: FloatArray, single: bool) -> FloatArray:
    return x[0] if single else x


def validate_rotation(
    R: ArrayLike, name: str = "R", *, atol: float = DEFAULT_ATOL, batch: bool = False
) -> FloatArray:
    """Check that ``R`` is a rotation matrix and return it as C-contiguous float64.

    Parameters
    ----------
    R : array_like of shape (3, 3), or (N, 3, 3) when ``batch``
        The matrix (matrices) to check.
    name : str
        Name of the argument, used in the error message.
    atol : float
        Tolerance on ``max |R^T R - I|`` and ``|det R - 1|``.
    batch : bool
        Also accept a leading batch dimension.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
        ``R`` itself when it already is C-contiguous float64.

    Raises
    ------
    ValueError
        Wrong shape, non-finite values, not orthonormal, or a reflection (det -1).
    """
    R_checked, single = _batch_arg(R, name, (3, 3), batch=batch)
    _check_rotations(R_checked, name, atol, single)
    return _unbatch(R_checked, single)


def validate_T(
    T: ArrayLike, name: str = "T", *, atol: float = DEFAULT_ATOL, batch: bool = False
) -> FloatArray:
    """Check that ``T`` is a rigid transform and return it as C-contiguous float64.

    A rigid transform is a finite 4 x 4 matrix whose top-left 3 x 3 block is a rotation
    (orthonormal, det +1) and whose last row is ``[0, 0, 0, 1]``, all within ``atol``.

    Parameters
    ----------
    T : array_like of shape (4, 4), or (N, 4, 4) when ``batch``
        The transform(s) to check, e.g. ``T_camera_lidar``.
    name : str
        Name of the argument, used in the error message.
    atol : float
        Tolerance of the rotation and last-row checks.
    batch : bool
        Also accept a leading batch dimension.

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
        ``T`` itself when it already is C-contiguous float64.

    Raises
    ------
    ValueError
        Naming ``name`` and what is wrong.
    """
    T_checked, single = _batch_arg(T, name, (4, 4), batch=batch)
    _check_transforms(T_checked, name, atol, single)
    return _unbatch(T_checked, single)


def is_valid_T(T: ArrayLike, *, atol: float = DEFAULT_ATOL) -> bool:
    """Whether ``T`` is one finite 4 x 4 rigid transform (see :func:`validate_T`).

    Parameters
    ----------
    T : array_like
        Anything; only a (4, 4) rigid transform gives True.
    atol : float
        Tolerance of the rotation and last-row checks.

    Returns
    -------
    bool
    """
    try:
        validate_T(T, atol=atol)
    except ValueError:
        return False
    return True
