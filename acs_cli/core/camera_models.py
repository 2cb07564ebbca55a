"""Camera models of the bundle adjustments: projection and its analytic Jacobians.

Each model maps camera-frame points ``(..., 3)`` (OpenCV's optical frame: x right, y down,
z forward; metres) to pixels ``(..., 2)`` (OpenCV's: the top-left pixel's centre at 0)
through an intrinsic vector ``fx fy cx cy`` (pixels) followed by the model's distortion
coefficients in OpenCV's order (:data:`acs_cli.core.intrinsics.DISTORTION_NAMES`):

- ``pinhole``: ``k1 k2 p1 p2 k3`` (9 parameters; ``cv2.projectPoints``). ``k3`` is held by
  default, as the intrinsics stage does (``CALIB_FIX_K3``);
- ``rational``: ``k1 k2 p1 p2 k3 k4 k5 k6`` (12 parameters; ``cv2.projectPoints`` with
  ``CALIB_RATIONAL_MODEL``'s eight coefficients). ``k4 k5 k6`` are held by default: the
  numerator and the denominator trade off (to first order the radial factor is
  ``1 + (k1 - k4) r2``), so with all eight free a bundle slides along that valley without
  converging, while the numerator alone can absorb any change of the distortion. With
  ``x = X/Z``, ``y = Y/Z``, ``r2 = x^2 + y^2``::

      radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
      xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
      yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
      (u, v) = (fx xd + cx, fy yd + cy)

  (the pinhole model is this with ``k4 = k5 = k6 = 0``, and shares its code);
- ``fisheye``: the equidistant (Kannala-Brandt) model ``k1 k2 k3 k4`` (8 parameters;
  ``cv2.fisheye.projectPoints`` without skew). With ``rho = sqrt(X^2 + Y^2)`` and the angle
  off the optical axis ``theta = atan2(rho, Z)``::

      theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
      (u, v) = (fx theta_d X / rho + cx, fy theta_d Y / rho + cy)

  which is OpenCV's ``theta = atan(r)`` for ``Z > 0``.

Every function is vectorised over the points; none loops per point or per frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

__all__ = ["CAMERA_MODELS", "CameraModel", "camera_model"]

#: Below this ratio ``rho / Z`` the fisheye model's ``theta / rho`` and its derivative use
#: their series (the closed forms cancel catastrophically at the optical axis).
_AXIS_RATIO = 1e-4


def _rational(
    x_cam: FloatArray, p: FloatArray, jacobians: bool
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """Projection of ``(k, 3)`` points through the 12 rational parameters, with the
    Jacobians ``(k, 2, 12)`` (intrinsics) and ``(k, 2, 3)`` (point) when asked."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6 = p
    Z = x_cam[..., 2]
    x, y = x_cam[..., 0] / Z, x_cam[..., 1] / Z
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    uv = np.stack([fx * xd + cx, fy * yd + cy], axis=-1)
    if not jacobians:
        return uv, None, None
    k = x.size
    Di = np.zeros((k, 2, 12))
    Di[:, 0, 0], Di[:, 1, 1] = xd, yd
    Di[:, 0, 2], Di[:, 1, 3] = 1.0, 1.0
    powers = np.stack([r2, r2 * r2, r2 * r2 * r2], axis=-1)  # (k, 3)
    d_num = powers / den[:, None]  # d rad / d (k1, k2, k3)
    d_den = -(rad / den)[:, None] * powers  # d rad / d (k4, k5, k6)
    for cols, d in (([4, 5, 8], d_num), ([9, 10, 11], d_den)):
        Di[:, 0, cols] = fx * x[:, None] * d
        Di[:, 1, cols] = fy * y[:, None] * d
    Di[:, 0, 6], Di[:, 1, 6] = fx * 2.0 * x * y, fy * (r2 + 2.0 * y * y)  # p1
    Di[:, 0, 7], Di[:, 1, 7] = fx * (r2 + 2.0 * x * x), fy * 2.0 * x * y  # p2
    d_num_r2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    d_den_r2 = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (d_num_r2 - rad * d_den_r2) / den  # d rad / d r2
    # d(xd, yd) / d(x, y)
    a = rad + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
    b = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
    d = rad + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
    Dd = np.stack([np.stack([fx * a, fx * b], -1), np.stack([fy * b, fy * d], -1)], axis=1)
    # d(x, y) / d(X, Y, Z)
    Dn = np.zeros((k, 2, 3))
    Dn[:, 0, 0] = Dn[:, 1, 1] = 1.0 / Z
    Dn[:, 0, 2], Dn[:, 1, 2] = -x / Z, -y / Z
    return uv, Di, np.matmul(Dd, Dn)


def _pinhole(
    x_cam: FloatArray, p: FloatArray, jacobians: bool
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """The rational model with ``k4 = k5 = k6 = 0`` and its first 9 columns."""
    uv, Di, Dp = _rational(x_cam, np.concatenate([p, np.zeros(3)]), jacobians)
    return uv, None if Di is None else Di[:, :, :9], Dp


def _fisheye(
    x_cam: FloatArray, p: FloatArray, jacobians: bool
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """Equidistant projection of ``(k, 3)`` points through its 8 parameters, with the
    Jacobians ``(k, 2, 8)`` and ``(k, 2, 3)`` when asked."""
    fx, fy, cx, cy, k1, k2, k3, k4 = p
    X, Y, Z = x_cam[..., 0], x_cam[..., 1], x_cam[..., 2]
    rho2 = X * X + Y * Y
    rho = np.sqrt(rho2)
    theta = np.arctan2(rho, Z)
    t2 = theta * theta
    poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
    near = rho < _AXIS_RATIO * np.abs(Z)
    safe_rho = np.where(near, 1.0, rho)
    # theta / rho, by its series 1/Z - rho^2 / (3 Z^3) at the axis
    q = np.where(near, 1.0 / Z - rho2 / (3.0 * Z**3), theta / safe_rho)
    s = q * poly  # theta_d / rho
    xs, ys = s * X, s * Y
    uv = np.stack([fx * xs + cx, fy * ys + cy], axis=-1)
    if not jacobians:
        return uv, None, None
    k = X.size
    Di = np.zeros((k, 2, 8))
    Di[:, 0, 0], Di[:, 1, 1] = xs, ys
    Di[:, 0, 2], Di[:, 1, 3] = 1.0, 1.0
    tp = q[:, None] * np.stack([t2, t2**2, t2**3, t2**4], axis=-1)  # theta^(2j+1) / rho
    Di[:, 0, 4:] = fx * X[:, None] * tp
    Di[:, 1, 4:] = fy * Y[:, None] * tp
    dtheta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
    L2 = rho2 + Z * Z
    # h = (1 / rho) d s / d rho; its series at the axis is 2 (k1 - 1/3) / Z^3
    h = np.where(near, 2.0 * (k1 - 1.0 / 3.0) / Z**3, (dtheta_d * Z / L2 - s) / safe_rho**2)
    dz = -dtheta_d / L2  # d s / d Z = theta_d' (d theta / d Z) / rho; d(s X) / dZ = X dz
    Dp = np.empty((k, 2, 3))
    Dp[:, 0, 0] = fx * (s + X * X * h)
    Dp[:, 0, 1] = fx * X * Y * h
    Dp[:, 0, 2] = fx * X * dz
    Dp[:, 1, 0] = fy * X * Y * h
    Dp[:, 1, 1] = fy * (s + Y * Y * h)
    Dp[:, 1, 2] = fy * Y * dz
    return uv, Di, Dp


_Kernel = Callable[
    [FloatArray, FloatArray, bool], tuple[FloatArray, FloatArray | None, FloatArray | None]
]


@dataclass(frozen=True)
class CameraModel:
    """One camera model: its parameters, its projection and their derivatives.

    Attributes
    ----------
    name : str
        ``pinhole``, ``rational`` or ``fisheye`` (the intrinsics artifact's ``model``).
    names : tuple of str
        The intrinsic vector's parameters: ``fx fy cx cy`` then the distortion
        coefficients in OpenCV's order.
    held : tuple of str
        The parameters a bundle adjustment holds at their initial values by default.
    """

    name: str
    names: tuple[str, ...]
    held: tuple[str, ...]
    _kernel: _Kernel

    @property
    def size(self) -> int:
        """Length of the intrinsic vector."""
        return len(self.names)

    @property
    def distortion_names(self) -> tuple[str, ...]:
        return self.names[4:]

    def free(self, held: Sequence[str] | None = None) -> list[int]:
        """Indices of the parameters refined when ``held`` (default :attr:`held`) are held.

        Raises
        ------
        ValueError
            A held name that is not one of the model's parameters.
        """
        hold = self.held if held is None else tuple(held)
        unknown = [h for h in hold if h not in self.names]
        if unknown:
            raise ValueError(f"the {self.name} model has no parameter(s) {', '.join(unknown)}")
        return [i for i, n in enumerate(self.names) if n not in hold]

    def _check(self, intrinsics: FloatArray) -> FloatArray:
        p = np.asarray(intrinsics, dtype=float)
        if p.shape != (self.size,):
            raise ValueError(
                f"the {self.name} model takes {self.size} intrinsics "
                f"({' '.join(self.names)}), got shape {p.shape}"
            )
        return p

    def project(self, x_cam: FloatArray, intrinsics: FloatArray) -> FloatArray:
        """Pixels of camera-frame points.

        Parameters
        ----------
        x_cam : ndarray, shape (..., 3)
            Points in the camera's frame (metres), in front of it (``z > 0``).
        intrinsics : ndarray, shape (size,)
            Named by :attr:`names`.

        Returns
        -------
        ndarray, shape (..., 2)
            Pixels, as OpenCV's ``projectPoints`` of the model.
        """
        x = np.asarray(x_cam, dtype=float)
        return self._kernel(x, self._check(intrinsics), False)[0]

    def jacobians(self, x_cam: FloatArray, intrinsics: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Derivatives of :meth:`project` at ``(k, 3)`` points.

        Returns
        -------
        d_intrinsics : ndarray, shape (k, 2, size)
            Pixels per unit of each intrinsic parameter.
        d_point : ndarray, shape (k, 2, 3)
            Pixels per metre of the camera-frame point.
        """
        x = np.asarray(x_cam, dtype=float).reshape(-1, 3)
        _, Di, Dp = self._kernel(x, self._check(intrinsics), True)
        if Di is None or Dp is None:
            raise ValueError(f"the {self.name} model gave no Jacobian")
        return Di, Dp

    def vector(self, K: FloatArray, distortion: FloatArray) -> FloatArray:
        """The intrinsic vector ``(size,)`` from a camera matrix ``(3, 3)`` and the
        distortion coefficients (the pinhole model also takes four, ``k3 = 0``).

        Raises
        ------
        InputError
            A number of coefficients the model does not take.
        """
        d = np.asarray(distortion, dtype=float).ravel()
        m = self.size - 4
        sizes = (m - 1, m) if self.name == "pinhole" else (m,)
        if d.size not in sizes:
            raise InputError(
                f"the {self.name} model takes {m} distortion coefficients "
                f"({' '.join(self.distortion_names)}), got {d.size}"
            )
        Km = np.asarray(K, dtype=float)
        return np.concatenate([[Km[0, 0], Km[1, 1], Km[0, 2], Km[1, 2]], d, np.zeros(m - d.size)])


#: The models by name.
CAMERA_MODELS = {
    "pinhole": CameraModel(
        "pinhole", ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"), ("k3",), _pinhole
    ),
    "rational": CameraModel(
        "rational",
        ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
        ("k4", "k5", "k6"),
        _rational,
    ),
    "fisheye": CameraModel(
        "fisheye", ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"), (), _fisheye
    ),
}


def camera_model(name: str) -> CameraModel:
    """The model called ``name``; ``InputError`` naming the known ones otherwise."""
    try:
        return CAMERA_MODELS[name]
    except KeyError:
        raise InputError(
            f"unknown camera model {name!r} (known: {', '.join(CAMERA_MODELS)})"
        ) from None
