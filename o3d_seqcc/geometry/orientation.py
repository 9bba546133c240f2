"""The scene's up direction, from its cameras, and the rotation that makes it an engine's up axis (issue 13).

Reconstructions come in whatever frame the scanner or the structure-from-motion tool chose
(Fountain's is OpenCV's, y down); glTF is Y-up and engines (Unity, three.js, Godot) show such a
mesh upside down or on its side. The world up is estimated from the cameras
(:func:`estimate_up`): photos are taken with little roll, so every camera's x axis (OpenCV: right)
is nearly horizontal, and the up direction is the one most orthogonal to all of them (the
eigenvector of the smallest eigenvalue of the sum of their outer products), signed so that it
points along the cameras' mean up (-y) and backward (-z) directions. When all x axes are parallel
(one camera, or a single heading) that direction is ambiguous and the cameras' mean up direction
is used. :func:`up_axis_transform` maps the estimate to +Y (``"y"``, glTF) or +Z (``"z"``,
Blender / Unreal / MeshLab's default view), snapped to the nearest signed world axis within
:data:`SNAP_DEG` (scans are usually axis-aligned: the rotation is then exact, e.g. 180 degrees
about X for an OpenCV-frame scene, which keeps x and turns the cameras' viewing direction +z into
-z, a viewer's default), and is applied to positions and normals by the exporters.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["SNAP_DEG", "UP_AXES", "estimate_up", "up_axis_transform"]

#: targets of :func:`up_axis_transform`
UP_AXES = ("y", "z", "none")
#: an estimated up within this many degrees of a signed world axis is taken to be that axis
SNAP_DEG = 15.0
_AXES = ("+x", "+y", "+z", "-x", "-y", "-z")


def _extrinsics(scene_or_extrinsics: Any) -> np.ndarray:
    views = getattr(scene_or_extrinsics, "views", None)
    ext = [v.extrinsic for v in views] if views is not None else list(scene_or_extrinsics)
    E = np.asarray(ext, dtype=np.float64)
    if E.ndim != 3 or E.shape[1:] != (4, 4) or len(E) == 0:
        raise InputError(f"up axis: expected a scene or (V, 4, 4) world-to-camera extrinsics, got shape {E.shape}")
    return E


def estimate_up(scene_or_extrinsics: Any) -> tuple[np.ndarray, dict[str, Any]]:
    """The world up direction of a scene, from its cameras (see the module docstring).

    Parameters
    ----------
    scene_or_extrinsics : Scene or sequence of (4, 4) arrays
        World-to-camera extrinsics, OpenCV axes (x right, y down, z forward).

    Returns
    -------
    up : (3,) float64
        Unit vector, scene coordinates.
    info : dict
        ``method`` ("camera x axes" or "mean camera up"), ``x_axes_tilt_deg`` (RMS angle of the
        cameras' x axes out of the horizontal plane), ``views``.
    """
    E = _extrinsics(scene_or_extrinsics)
    Rt = np.transpose(E[:, :3, :3], (0, 2, 1))  # camera axes in world coordinates (columns)
    x, y, z = Rt[:, :, 0], Rt[:, :, 1], Rt[:, :, 2]
    mean_up = -y.mean(axis=0)
    hint = mean_up - z.mean(axis=0)
    w, V = np.linalg.eigh(x.T @ x / len(x))
    if w[1] > 0.05:  # the x axes span a plane: up is its normal
        up, method = V[:, 0], "camera x axes"
        if float(up @ hint) < 0:
            up = -up
    else:  # parallel x axes: the cameras' mean up, made orthogonal to them
        xm = x.mean(axis=0) / max(np.linalg.norm(x.mean(axis=0)), 1e-12)
        up, method = mean_up - (mean_up @ xm) * xm, "mean camera up"
    n = float(np.linalg.norm(up))
    if not n > 1e-9:
        raise InputError("up axis: the cameras do not define an up direction; use up_axis='none'")
    up = up / n
    tilt = float(np.degrees(np.arcsin(np.sqrt(np.clip((x @ up) ** 2, 0.0, 1.0).mean()))))
    return up, {"method": method, "x_axes_tilt_deg": tilt, "views": int(len(E))}


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation (det +1) taking unit vector a to unit vector b by the shortest arc."""
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:  # opposite: 180 degrees about the x axis made orthogonal to a (y if a is along x)
        ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis = ref - (ref @ a) * a
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def up_axis_transform(scene_or_extrinsics: Any, up_axis: str = "y") -> tuple[np.ndarray, dict[str, Any]]:
    """The rotation that makes the scene's up direction the ``up_axis`` of the exported files.

    Parameters
    ----------
    scene_or_extrinsics : Scene or sequence of (4, 4) arrays
    up_axis : {"y", "z", "none"}, default "y"
        ``"y"``: glTF's (and most engines') up; ``"z"``: Blender's, Unreal's; ``"none"``: the
        scene's own frame (identity).

    Returns
    -------
    rotation : (3, 3) float64
        Applied as ``p' = rotation @ p`` to positions and normals.
    info : dict
        ``up_axis``, ``rotation`` (nested lists), and unless ``"none"``: ``scene_up`` (the
        estimate, scene coordinates), ``nearest_axis`` (e.g. "-y"), ``angle_deg`` (between the
        estimate and that axis), ``snapped``, ``method``, ``x_axes_tilt_deg``, ``views``.

    Raises
    ------
    InputError
        An unknown ``up_axis``, or cameras that define no up direction.
    """
    key = str(up_axis).lower()
    if key not in UP_AXES:
        raise InputError(f"unknown up axis {up_axis!r}; valid: {', '.join(UP_AXES)}")
    if key == "none":
        return np.eye(3), {"up_axis": "none", "rotation": np.eye(3).tolist()}
    up, info = estimate_up(scene_or_extrinsics)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    k = int(np.argmax(axes @ up))
    angle = float(np.degrees(np.arccos(np.clip(axes[k] @ up, -1.0, 1.0))))
    snapped = angle <= SNAP_DEG
    src = axes[k] if snapped else up
    dst = np.array([0.0, 1.0, 0.0]) if key == "y" else np.array([0.0, 0.0, 1.0])
    R = _rotation_between(src, dst)
    R[np.abs(R) < 1e-12] = 0.0
    info = {"up_axis": key, "rotation": R.tolist(), "scene_up": up.tolist(), "nearest_axis": _AXES[k],
            "angle_deg": angle, "snapped": bool(snapped), **info}
    return R, info
