"""Camera calibration files: ``cameras.json``, OpenCV YAML/XML, Qualisys ``.qca.txt``.

``Calib.toml`` (Pose2Sim, anipose, FreeMoCap) has its own module, `mocapkit.io.calib_toml`.

``cameras.json`` (format 1)::

    {"format": 1,
     "cameras": [{"name": "left", "image_size": [w, h], "K": 3x3 (px),
                  "dist": [k1, k2, p1, p2, k3, ...], "camera_from_world": 4x4 (mm)}]}

Every reader validates strictly and raises `FormatError` naming the file, the
field, what was expected and what was found.
"""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import FormatError
from mocapkit.geometry.transforms import make_transform
from mocapkit.io.atomic import atomic_write
from mocapkit.io.calib_toml import read_calib_toml
from mocapkit.io.camera_checks import (
    DIST_LENGTHS,
    camera_from_entry,
    check_rotation,
    check_unique_names,
    number_array,
)
from mocapkit.io.files import read_text, require_file

FORMAT_VERSION = 1
PathLike = str | os.PathLike[str]


# ----------------------------------------------------------------------------- cameras.json


def cameras_from_document(doc: Any, source: str) -> list[Camera]:
    """Validate a parsed ``cameras.json`` document and build its cameras.

    Parameters
    ----------
    doc : object
        The parsed JSON value.
    source : str
        Where it came from, used in error messages.
    """
    if not isinstance(doc, dict):
        raise FormatError(
            f"{source}: expected a JSON object at top level, found {type(doc).__name__}"
        )
    if "format" not in doc:
        raise FormatError(f"{source}: missing key 'format'; expected \"format\": {FORMAT_VERSION}")
    version = doc["format"]
    if version != FORMAT_VERSION or isinstance(version, bool):
        raise FormatError(
            f"{source}: format: expected version {FORMAT_VERSION}, found {version!r} "
            "(written by a different mocapkit version?)"
        )
    extra = sorted(set(doc) - {"format", "cameras"})
    if extra:
        raise FormatError(
            f"{source}: unknown top-level key(s) {', '.join(extra)}; expected format, cameras"
        )
    if "cameras" not in doc:
        raise FormatError(f"{source}: missing key 'cameras'")
    entries = doc["cameras"]
    if not isinstance(entries, list) or not entries:
        raise FormatError(f"{source}: cameras: expected a non-empty list, found {entries!r}")
    cameras = [camera_from_entry(e, f"{source}: cameras[{i}]") for i, e in enumerate(entries)]
    check_unique_names([c.name for c in cameras], source)
    return cameras


def read_cameras(path: PathLike) -> list[Camera]:
    """Read a ``cameras.json`` file (format 1) into a list of `Camera`.

    Raises `FormatError` naming the file and the field on any deviation.
    """
    p = Path(path)
    text = read_text(p, "camera file")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"{p}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from exc
    return cameras_from_document(doc, str(p))


def _num(x: float) -> str:
    return json.dumps(float(x))


def _row(values: Any) -> str:
    return "[" + ", ".join(_num(v) for v in np.ravel(values)) + "]"


def write_cameras(path: PathLike, cameras: Sequence[Camera]) -> None:
    """Write cameras to ``path`` as ``cameras.json`` (format 1), atomically.

    Matrices are written row by row at full double precision, so
    `read_cameras` returns bit-identical values.
    """
    cams = list(cameras)
    if not cams:
        raise FormatError(f"{path}: cameras: expected at least one camera to write, found none")
    for i, c in enumerate(cams):
        if not isinstance(c, Camera):
            raise FormatError(f"{path}: cameras[{i}]: expected a Camera, found {type(c).__name__}")
    check_unique_names([c.name for c in cams], str(path))
    blocks = []
    for c in cams:
        k_rows = ",\n        ".join(_row(r) for r in c.K)
        m_rows = ",\n        ".join(_row(r) for r in c.camera_from_world)
        blocks.append(
            "    {\n"
            f'      "name": {json.dumps(c.name)},\n'
            f'      "image_size": [{c.image_size[0]}, {c.image_size[1]}],\n'
            f'      "K": [\n        {k_rows}\n      ],\n'
            f'      "dist": {_row(c.dist)},\n'
            f'      "camera_from_world": [\n        {m_rows}\n      ]\n'
            "    }"
        )
    text = (
        f'{{\n  "format": {FORMAT_VERSION},\n  "cameras": [\n' + ",\n".join(blocks) + "\n  ]\n}\n"
    )
    json.loads(text)  # the hand layout must stay valid JSON
    with atomic_write(path, "w") as fh:
        fh.write(text)


# ----------------------------------------------------------------------------- OpenCV FileStorage

_K_KEYS = ("camera_matrix", "cameraMatrix", "K")
_DIST_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "dist")


def read_opencv_calibration(
    path: PathLike, name: str | None = None, translation_mm_per_unit: float = 1.0
) -> Camera:
    """Read a single-camera OpenCV YAML/XML calibration (`cv2.FileStorage`).

    Reads the intrinsic matrix (``camera_matrix``), distortion
    (``distortion_coefficients``) and image size (``image_width``/``image_height``
    or ``image_size``), as written by OpenCV's calibration sample. Extrinsics are
    read from ``R`` (3x3 or a Rodrigues 3-vector) and ``T`` when both are present
    (world -> camera, ``T`` multiplied by ``translation_mm_per_unit``); otherwise
    the camera frame is the world.

    Parameters
    ----------
    path : path-like
    name : str, optional
        Camera name; defaults to the file's stem.
    translation_mm_per_unit : float
        mm per unit of ``T`` (1000 if the file is in metres).
    """
    import cv2

    p = require_file(path, "OpenCV calibration file")
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise FormatError(f"{p}: not a readable OpenCV YAML/XML file ({str(exc).strip()})") from exc
    try:
        if not fs.isOpened():
            raise FormatError(f"{p}: not a readable OpenCV YAML/XML file")

        def node_mat(keys: Sequence[str]) -> tuple[str, NDArray[np.float64]] | None:
            for key in keys:
                node = fs.getNode(key)
                if not node.empty():
                    mat = node.mat()
                    if mat is None:
                        raise FormatError(
                            f"{p}: {key}: expected an opencv-matrix, found another node type"
                        )
                    return key, np.asarray(mat, dtype=float)
            return None

        found_k = node_mat(_K_KEYS)
        if found_k is None:
            raise FormatError(
                f"{p}: missing camera matrix; expected one of the keys {', '.join(_K_KEYS)}"
            )
        k = number_array(found_k[1], (3, 3), f"{p}: {found_k[0]}")
        found_d = node_mat(_DIST_KEYS)
        dist = np.zeros(0) if found_d is None else np.ravel(found_d[1])
        if dist.shape[0] not in DIST_LENGTHS:
            raise FormatError(
                f"{p}: {found_d[0] if found_d else 'distortion'}: expected "
                f"{', '.join(map(str, DIST_LENGTHS))} coefficients, found {dist.shape[0]}"
            )
        w_node, h_node = fs.getNode("image_width"), fs.getNode("image_height")
        size_node = fs.getNode("image_size")
        if size_node.empty():
            size_node = fs.getNode("imageSize")
        if not w_node.empty() and not h_node.empty():
            size = (int(w_node.real()), int(h_node.real()))
        elif not size_node.empty():
            if size_node.isSeq():
                vals = [size_node.at(i).real() for i in range(size_node.size())]
            else:
                vals = list(np.ravel(size_node.mat()))
            if len(vals) != 2:
                raise FormatError(f"{p}: image_size: expected [width, height], found {vals}")
            size = (int(vals[0]), int(vals[1]))
        else:
            raise FormatError(
                f"{p}: missing image size; expected image_width and image_height, or image_size"
            )
        if size[0] <= 0 or size[1] <= 0:
            raise FormatError(f"{p}: image size: expected positive width and height, found {size}")
        m = np.eye(4)
        r_found, t_found = node_mat(("R",)), node_mat(("T",))
        if (r_found is None) != (t_found is None):
            raise FormatError(f"{p}: extrinsics: expected both R and T or neither, found only one")
        if r_found is not None and t_found is not None:
            r_raw = r_found[1]
            if r_raw.size == 3:
                r_raw = np.asarray(cv2.Rodrigues(r_raw.reshape(3, 1))[0], dtype=float)
            r = number_array(r_raw, (3, 3), f"{p}: R")
            check_rotation(r, f"{p}: R", tol=1e-5)
            t = number_array(np.ravel(t_found[1]), (3,), f"{p}: T") * translation_mm_per_unit
            m = make_transform(r, t)
    finally:
        fs.release()
    return Camera(name if name is not None else p.name.split(".")[0], size, k, dist, m)


# ----------------------------------------------------------------------------- Qualisys .qca.txt

# Qualisys cameras look along their -z axis with y up; OpenCV's look along +z with y
# down. Flipping y and z (a pi rotation about x) converts one into the other.
_QTM_TO_OPENCV = np.diag([1.0, -1.0, -1.0])


def _attr_float(elem: ET.Element, key: str, where: str) -> float:
    raw = elem.get(key)
    if raw is None:
        raise FormatError(f"{where}: missing attribute {key!r}")
    try:
        val = float(raw)
    except ValueError as exc:
        raise FormatError(f"{where}: {key}: expected a number, found {raw!r}") from exc
    if not math.isfinite(val):
        raise FormatError(f"{where}: {key}: expected a finite number, found {raw!r}")
    return val


def _child(elem: ET.Element, tag: str, where: str) -> ET.Element:
    found = elem.find(tag)
    if found is None:
        raise FormatError(f"{where}: missing element <{tag}>")
    return found


def _subpixel_factor(cam: ET.Element, intr: ET.Element, where: str) -> int:
    """Sensor sub-pixel units per pixel, from sensorMax* over the full-sensor field of view.

    The field-of-view elements give the last pixel index (e.g. right = 1087),
    sensorMaxU that index in sub-pixel units (69568 = 1087 x 64); files differ on
    whether sensorMax* is the last index x 64 or the width x 64 - 1, so the ratio
    is rounded to an integer.
    """
    fov = cam.find("fov_marker_max")
    if fov is None:
        fov = _child(cam, "fov_video_max", where)
    ratios = []
    for axis, lo, hi in (("U", "left", "right"), ("V", "top", "bottom")):
        span_px = _attr_float(fov, hi, f"{where} <{fov.tag}>") - _attr_float(
            fov, lo, f"{where} <{fov.tag}>"
        )
        span_sub = _attr_float(intr, f"sensorMax{axis}", f"{where} <intrinsic>") - _attr_float(
            intr, f"sensorMin{axis}", f"{where} <intrinsic>"
        )
        if span_px <= 0 or span_sub <= 0:
            raise FormatError(
                f"{where}: sensor extent along {axis}: expected positive, "
                f"found {span_px} px and {span_sub} units"
            )
        ratios.append(span_sub / span_px)
    factor = round(ratios[0])
    if factor < 1 or any(abs(r - factor) > 0.02 * factor for r in ratios):
        raise FormatError(
            f"{where}: sub-pixel factor (sensorMax / field of view): expected the same integer "
            f"along U and V, found {ratios[0]:.3f} and {ratios[1]:.3f}"
        )
    return factor


def read_qualisys(path: PathLike, binning_factor: int = 1) -> list[Camera]:
    """Read a Qualisys QTM calibration (``.qca.txt`` XML) into OpenCV-convention cameras.

    Conventions, checked on the Pose2Sim demo rig (the optical axes of all four
    cameras meet in front of every camera, near their image centres):

    * ``transform`` holds the camera *pose*: ``x, y, z`` is the optical centre in
      world mm, and ``R = [[r11, r12, r13], ...]`` maps world to a camera frame
      with y up and z backwards, so ``camera_from_world`` rotation is
      ``diag(1, -1, -1) @ R`` and its translation ``-rotation @ [x, y, z]``.
    * Image-plane intrinsics (focal lengths, principal point, skew) are in sensor
      sub-pixel units; the factor (64 in QTM) is derived from ``sensorMaxU/V``
      over the full-sensor field of view. The principal point is shifted by the
      video window's ``left``/``top`` and everything is divided by
      ``binning_factor``.
    * Distortion coefficients are dimensionless (normalised image coordinates)
      and are used as they are: ``[k1, k2, p1, p2, k3]`` = radialDistortion1, 2,
      tangentalDistortion1, 2, radialDistortion3. (Pose2Sim also divides them by
      64, which makes them ~64 times too small: an independent checkerboard
      calibration of the demo's camera 1 matches the unscaled values.)
    * The image size is the ``fov_video`` window, inclusive (``right - left + 1``),
      divided by ``binning_factor`` (the Pose2Sim demo's cam01/cam02 videos are
      1080 px wide, 8 px narrower than this window). Only cameras with ``active="1"`` are read;
      ``viewrotation`` other than 0 is refused.

    Parameters
    ----------
    path : path-like
    binning_factor : int
        Video pixels binning relative to the sensor (1 = none).
    """
    p = Path(path)
    if binning_factor < 1:
        raise FormatError(
            f"{p}: binning_factor: expected a positive integer, found {binning_factor}"
        )
    require_file(p, "Qualisys calibration file")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise FormatError(f"{p}: not valid XML ({exc})") from exc
    if root.tag != "calibration":
        raise FormatError(f"{p}: expected root element <calibration>, found <{root.tag}>")
    cam_elems = root.findall("cameras/camera")
    if not cam_elems:
        raise FormatError(f"{p}: no <cameras>/<camera> elements found")
    cameras = []
    for i, cam in enumerate(cam_elems):
        name = cam.get("serial") or f"camera{i + 1}"
        where = f"{p}: camera {i} (serial {name!r})"
        if cam.get("active", "1") != "1":
            continue
        rotation_attr = cam.get("viewrotation", "0")
        if rotation_attr != "0":
            raise FormatError(
                f"{where}: viewrotation: expected 0 (unrotated view), found {rotation_attr!r}"
            )
        tr = _child(cam, "transform", where)
        r_qtm = np.array(
            [[_attr_float(tr, f"r{a}{b}", f"{where} <transform>") for b in "123"] for a in "123"]
        )
        check_rotation(r_qtm, f"{where} <transform> r11..r33", tol=1e-5)
        centre_mm = np.array([_attr_float(tr, k, f"{where} <transform>") for k in "xyz"])
        intr = _child(cam, "intrinsic", where)
        factor = _subpixel_factor(cam, intr, where)
        fov = _child(cam, "fov_video", where)
        left = _attr_float(fov, "left", f"{where} <fov_video>")
        top = _attr_float(fov, "top", f"{where} <fov_video>")
        width = (_attr_float(fov, "right", f"{where} <fov_video>") - left + 1) / binning_factor
        height = (_attr_float(fov, "bottom", f"{where} <fov_video>") - top + 1) / binning_factor

        def sub(
            key: str, intr: ET.Element = intr, where: str = where, factor: int = factor
        ) -> float:
            return _attr_float(intr, key, f"{where} <intrinsic>") / factor

        fx = sub("focalLengthU") / binning_factor
        fy = sub("focalLengthV") / binning_factor
        skew = (sub("skew") / binning_factor) if intr.get("skew") is not None else 0.0
        cx = (sub("centerPointU") - left) / binning_factor
        cy = (sub("centerPointV") - top) / binning_factor
        k = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

        def coef(key: str, intr: ET.Element = intr, where: str = where) -> float:
            return (
                _attr_float(intr, key, f"{where} <intrinsic>") if intr.get(key) is not None else 0.0
            )

        dist = np.array(
            [
                coef("radialDistortion1"),
                coef("radialDistortion2"),
                coef("tangentalDistortion1"),
                coef("tangentalDistortion2"),
                coef("radialDistortion3"),
            ]
        )
        rot = _QTM_TO_OPENCV @ r_qtm
        cameras.append(
            Camera(
                name, (round(width), round(height)), k, dist, make_transform(rot, -rot @ centre_mm)
            )
        )
    if not cameras:
        raise FormatError(f"{p}: no active cameras (every <camera> has active != 1)")
    check_unique_names([c.name for c in cameras], str(p))
    return cameras


def load_cameras(path: PathLike, unit: str | None = None) -> list[Camera]:
    """Read cameras from any supported file, chosen by name.

    ``*.json`` -> `read_cameras`; ``*.toml`` -> `mocapkit.io.calib_toml.read_calib_toml`
    (Pose2Sim, anipose, FreeMoCap; ``unit`` is its translations' unit, ``"m"`` or
    ``"mm"``, read from their size when None); ``*.qca.txt`` / ``*.qca`` ->
    `read_qualisys`; ``*.yml`` / ``*.yaml`` / ``*.xml`` -> one camera from
    `read_opencv_calibration`, named by the file's stem.
    """
    p = Path(path)
    if p.is_dir():
        raise FormatError(f"{p}: expected a calibration file, found a folder")
    low = p.name.lower()
    if not low.endswith((".toml", ".json", ".qca.txt", ".qca", ".yml", ".yaml", ".xml")):
        raise FormatError(
            f"{p}: unknown camera file type; expected .json, .toml, .qca.txt, .yml, .yaml or .xml"
        )
    if not p.exists():
        raise FormatError(f"{p}: calibration file not found")
    if low.endswith(".toml"):
        return read_calib_toml(p, unit)
    if unit is not None:
        raise FormatError(
            f"{p}: a translation unit ({unit!r}) is only read for Calib.toml files; this "
            "format states its own"
        )
    if low.endswith(".json"):
        return read_cameras(p)
    if low.endswith((".qca.txt", ".qca")):
        return read_qualisys(p)
    return [read_opencv_calibration(p)]  # .yml, .yaml, .xml
