"""OpenPose JSON keypoint folders (BODY_25, COCO-18) read as canonical 2-D keypoints.

OpenPose (``--write_json``), Pose2Sim, Sports2D and EasyMocap write one JSON file per
frame::

    {"version": 1.3, "people": [{"person_id": [-1],
                                 "pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...]}, ...]}

with 25 (BODY_25) or 18 (COCO-18) keypoints per person, pixel positions and a confidence
in [0, 1]. Files are taken in the order of the frame number in their names
(`mocapkit.io.frame_files`: ``frame_2`` before ``frame_10``; gaps and repeats refused).
A point whose confidence is below ``min_confidence`` (or written as 0, 0, 0) is missing.

Mapping onto canonical joints (`CANONICAL_JOINTS`):

- shoulders, elbows, wrists, hips, knees, ankles: the detector's points of the same name;
- head: our head point is the centre of the head, not the nose: the midpoint of the two
  ears; with one ear or none, the mean of the ears and eyes seen (biased towards the face);
  missing when neither ears nor eyes are seen;
- neck and pelvis: the detector's "Neck" is the midpoint of the shoulders and "MidHip" that
  of the hips; ours are the neck base and the pelvis centre, which no detector marks. Both
  lie near the line from the hip midpoint M_h to the shoulder midpoint M_s (10th-90th
  percentiles of their distance from it on the CMU clips the library reads: the neck's
  under 0.045 of its length, the pelvis's under 0.15):
  neck = M_h + f_n (M_s - M_h), pelvis = M_h + f_p (M_s - M_h); missing unless both
  shoulders and both hips are seen. The fractions are a property of the subject more than
  of the pose (f_n within 0.005 of its median over a clip, f_p within 0.02, 10th-90th
  percentiles; a subject hanging from a bar 0.85-0.91 and 0.11-0.21), but differ between
  subjects and skeleton sources (f_n 0.80-0.93, f_p 0.18-0.27), so a fixed pair puts the
  neck up to 0.12 of the trunk off. What varies far less is the shoulder girdle: the neck sits
  ``NECK_BELOW_SHOULDERS`` = 0.205 shoulder widths W below M_s and the pelvis
  ``PELVIS_ABOVE_HIPS`` = 0.277 shoulder widths above M_h, along the trunk (per clip
  0.178-0.237 and 0.249-0.304 over the ten CMU clips, one dancer's neck 0.100 aside; the
  same take as BVH and as AMC gives f_n 0.811 and 0.854 but 0.205 and 0.204
  W; docs/design-notes/mono.md). So `read_openpose_folder`
  places them per take (`trunk_fractions`): f_n = 1 - 0.205 W / H, f_p = 0.277 W / H,
  with W and H (the length M_h-M_s) the 90th percentiles of their projected lengths
  over the frames that see both shoulders and both hips, as the link lengths are read
  off the video (§4.1: each seen near parallel to the image at least once). A take
  without such a frame, or with W / H so large that the neck would fall below the
  pelvis, keeps the fixed pair ``NECK_FRACTION`` 0.81 and ``PELVIS_FRACTION`` 0.25 (the
  clips' medians), which `to_canonical` also uses frame by frame (for following).

Several people: one person is followed through the video by the rule `mocapkit detect`
follows them with (`mocapkit.cues.follow.PersonFollower`), on the file's own keypoints
seen with at least ``min_confidence``: the largest person of the first frame with anyone
seen, or the one at a given image point; then in each frame the person nearest the
followed one's last seen points, if near enough and of a like size; otherwise nobody
(NaN). Everyone else is ignored. On a folder `mocapkit detect` wrote (the person it
followed, or nobody, per frame) this keeps every frame it wrote.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.cues.follow import MIN_CONFIDENCE, PersonFollower, seen_points
from mocapkit.errors import ConfigError, FormatError, SessionError, ShapeError
from mocapkit.io.files import read_text
from mocapkit.io.frame_files import in_frame_order
from mocapkit.io.session_csv import Keypoints

FloatArray = NDArray[np.float64]

BODY_25: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar",
    "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)  # fmt: skip
COCO_18: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar",
)  # fmt: skip
LAYOUTS: dict[int, tuple[str, tuple[str, ...]]] = {
    25: ("BODY_25", BODY_25),
    18: ("COCO-18", COCO_18),
}

#: Canonical joints taken directly from a detector point of the same body part.
DIRECT: dict[str, str] = {
    "left_shoulder": "LShoulder",
    "left_elbow": "LElbow",
    "left_wrist": "LWrist",
    "right_shoulder": "RShoulder",
    "right_elbow": "RElbow",
    "right_wrist": "RWrist",
    "left_hip": "LHip",
    "left_knee": "LKnee",
    "left_ankle": "LAnkle",
    "right_hip": "RHip",
    "right_knee": "RKnee",
    "right_ankle": "RAnkle",
}
#: Where the canonical neck and pelvis sit on the line from the hip to the shoulder midpoint
#: when the take gives no estimate of its own (medians over the CMU clips).
NECK_FRACTION = 0.81
PELVIS_FRACTION = 0.25
#: The neck's distance below the shoulder midpoint and the pelvis's above the hip midpoint,
#: along the trunk, in shoulder widths (3-D; medians over the ten CMU clips of
#: ``shared/data/mocap`` as the library reads them, one take as both BVH and AMC: the
#: truth's canonical joints, per frame, then the median per clip; left one subject
#: out, the medians move by at most 0.0015 and 0.004).
NECK_BELOW_SHOULDERS = 0.205
PELVIS_ABOVE_HIPS = 0.277
#: The canonical joints this mapping rebuilds rather than reads off the detector.
REBUILT_JOINTS: tuple[str, ...] = ("neck", "pelvis")
#: Cosine of the angle between the two clavicles (neck to each shoulder) of the girdle that
#: the placement assumes: the neck ``NECK_BELOW_SHOULDERS`` = d shoulder widths below the
#: shoulder midpoint, so each clavicle is (+-1/2, d) W and the cosine (d^2 - 1/4) /
#: (d^2 + 1/4) = -0.712 (135 deg; on the CMU clips constant within a clip to three
#: decimals, e.g. -0.710; the dancer whose neck sits 0.100 W down, -0.922).
GIRDLE_COSINE = (NECK_BELOW_SHOULDERS**2 - 0.25) / (NECK_BELOW_SHOULDERS**2 + 0.25)

#: Canonical joints the mapping provides, in canonical order.
MAPPED_JOINTS: tuple[str, ...] = (
    "head", "neck", "pelvis", "left_shoulder", "left_elbow", "left_wrist", "right_shoulder",
    "right_elbow", "right_wrist", "left_hip", "left_knee", "left_ankle", "right_hip",
    "right_knee", "right_ankle",
)  # fmt: skip


def openpose_files(folder: str | os.PathLike[str]) -> list[Path]:
    """The JSON files of a keypoint folder in frame order: by the number in their names,
    without gaps or repeats (`mocapkit.io.frame_files`)."""
    p = Path(folder)
    if not p.is_dir():
        raise SessionError(
            f"{p}: expected an OpenPose keypoint folder, found a file"
            if p.exists()
            else f"{p}: OpenPose keypoint folder not found"
        )
    files = [f for f in p.iterdir() if f.suffix.lower() == ".json"]
    if not files:
        cams = sorted(
            d.name
            for d in p.iterdir()
            if d.is_dir() and any(f.suffix.lower() == ".json" for f in d.iterdir())
        )
        if cams:
            shown = ", ".join(cams[:6]) + (f" and {len(cams) - 6} more" if len(cams) > 6 else "")
            raise SessionError(
                f"{p}: expected OpenPose JSON files (one per frame), found none but "
                f"subfolders of them, one per camera ({shown}): pass one camera's folder: "
                f"{p / cams[0]}"
            )
        raise SessionError(f"{p}: expected OpenPose JSON files (one per frame), found none")
    return in_frame_order(files, p, "OpenPose JSON files")


def read_openpose_frame(path: str | os.PathLike[str]) -> tuple[str, FloatArray]:
    """The people of one OpenPose JSON file.

    Returns
    -------
    layout : str
        ``"BODY_25"`` or ``"COCO-18"`` (``""`` when the frame holds nobody).
    people : (P, J, 3) float
        x_px, y_px, confidence per keypoint.
    """
    p = Path(path)
    try:
        doc = json.loads(read_text(p, "OpenPose JSON"))
    except json.JSONDecodeError as exc:
        raise FormatError(f"{p}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("people"), list):
        raise FormatError(f"{p}: expected an object with a 'people' list, found {type(doc)}")
    rows: list[FloatArray] = []
    layout = ""
    for i, person in enumerate(doc["people"]):
        flat = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        where = f"{p}: people[{i}].pose_keypoints_2d"
        if not isinstance(flat, list):
            raise FormatError(f"{where}: expected a list of numbers, found {type(flat).__name__}")
        for k, v in enumerate(flat):
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise FormatError(
                    f"{where}[{k}]: expected a number, found {v!r} ({type(v).__name__})"
                )
        n = len(flat) // 3
        if len(flat) % 3 or n not in LAYOUTS:
            raise FormatError(
                f"{where}: expected 75 (BODY_25) or 54 (COCO-18) numbers, found {len(flat)}"
            )
        conf = flat[2::3]
        bad = [k for k, c in enumerate(conf) if not 0.0 <= c <= 1.0]
        if bad:
            k = bad[0]
            raise FormatError(
                f"{where}: keypoint {k} ({LAYOUTS[n][1][k]}) confidence: expected a number in "
                f"[0, 1], found {conf[k]!r} ({len(bad)} such keypoints in this person)"
            )
        name = LAYOUTS[n][0]
        if layout and name != layout:
            raise FormatError(f"{p}: people[{i}]: {name} keypoints after {layout} ones")
        layout = name
        rows.append(np.asarray(flat, dtype=float).reshape(n, 3))
    n_kp = len(LAYOUTS_BY_NAME[layout]) if layout else 0
    return layout, np.stack(rows) if rows else np.zeros((0, n_kp, 3))


LAYOUTS_BY_NAME: dict[str, tuple[str, ...]] = {name: kps for name, kps in LAYOUTS.values()}


def to_canonical(
    people: ArrayLike,
    layout: str,
    min_confidence: float = MIN_CONFIDENCE,
    fractions: tuple[float, float] = (NECK_FRACTION, PELVIS_FRACTION),
) -> FloatArray:
    """Map detector keypoints (P, J, 3) onto canonical joints (P, len(MAPPED_JOINTS), 2).

    See the module docstring for the mapping; NaN where a joint is missing. ``fractions``
    places the neck and pelvis on the hip-to-shoulder midpoint line (`trunk_fractions`
    gives a take's own; one frame alone cannot).
    """
    if layout not in LAYOUTS_BY_NAME:
        raise FormatError(
            f"OpenPose layout: expected one of {sorted(LAYOUTS_BY_NAME)}, found {layout!r}"
        )
    names = LAYOUTS_BY_NAME[layout]
    pp = np.asarray(people, dtype=float)
    if pp.ndim != 3 or pp.shape[1:] != (len(names), 3):
        raise ShapeError(f"to_canonical: expected ({len(names)}, 3) per person, found {pp.shape}")
    xy = pp[..., :2].copy()
    bad = (pp[..., 2] < min_confidence) | np.all(pp == 0.0, axis=-1)
    xy[bad] = np.nan

    def kp(name: str) -> FloatArray:
        return xy[:, names.index(name)]

    out = np.full((pp.shape[0], len(MAPPED_JOINTS), 2), np.nan)
    col = {n: i for i, n in enumerate(MAPPED_JOINTS)}
    for joint, det in DIRECT.items():
        out[:, col[joint]] = kp(det)
    ears = np.stack([kp("LEar"), kp("REar")], axis=1)
    face = np.stack([kp("LEar"), kp("REar"), kp("LEye"), kp("REye")], axis=1)
    both_ears: NDArray[np.bool_] = np.asarray(np.isfinite(ears).all(axis=(1, 2)), dtype=bool)
    with np.errstate(invalid="ignore"), _quiet_nanmean():
        head = np.where(both_ears[:, None], ears.mean(axis=1), np.nanmean(face, axis=1))
    out[:, col["head"]] = head
    return place_trunk_joints(out, MAPPED_JOINTS, fractions)


def _trunk_points(
    pixels: FloatArray, joint_names: Sequence[str]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Shoulder midpoint, hip midpoint (..., 2) and shoulder-to-shoulder vector (..., 2)."""
    names = list(joint_names)

    def j(name: str) -> FloatArray:
        return pixels[..., names.index(name), :]

    m_s = 0.5 * (j("left_shoulder") + j("right_shoulder"))
    m_h = 0.5 * (j("left_hip") + j("right_hip"))
    return m_s, m_h, j("left_shoulder") - j("right_shoulder")


def place_trunk_joints(
    pixels: ArrayLike, joint_names: Sequence[str], fractions: tuple[float, float]
) -> FloatArray:
    """Canonical keypoints (..., K, 2) with the neck and pelvis rebuilt from the shoulders
    and hips: neck = M_h + f_n (M_s - M_h), pelvis = M_h + f_p (M_s - M_h).

    Parameters
    ----------
    pixels : (..., K, 2) float
        Canonical keypoints (px) of ``joint_names``, NaN where missing; must include
        both shoulders and hips, the neck and the pelvis.
    joint_names : sequence of str
    fractions : (f_n, f_p)
        Places of the neck and pelvis on the line from the hip midpoint M_h (0) to the
        shoulder midpoint M_s (1) (`trunk_fractions`).

    Returns
    -------
    (..., K, 2) float
        A copy; neck and pelvis NaN where a shoulder or hip is missing.
    """
    out = np.array(pixels, dtype=float)
    names = list(joint_names)
    if out.ndim < 2 or out.shape[-2:] != (len(names), 2):
        raise ShapeError(
            f"place_trunk_joints: expected (..., {len(names)}, 2) keypoints, found {out.shape}"
        )
    m_s, m_h, _ = _trunk_points(out, names)
    f_n, f_p = fractions
    out[..., names.index("neck"), :] = m_h + f_n * (m_s - m_h)
    out[..., names.index("pelvis"), :] = m_h + f_p * (m_s - m_h)
    return out


def trunk_fractions(
    pixels: ArrayLike, joint_names: Sequence[str], percentile: float = 90.0
) -> tuple[float, float]:
    """A take's neck and pelvis fractions from its shoulder width over its trunk.

    The shoulder girdle is rigid: the neck lies ``NECK_BELOW_SHOULDERS`` shoulder widths
    below the shoulder midpoint and the pelvis ``PELVIS_ABOVE_HIPS`` shoulder widths
    above the hip midpoint, along the trunk (module docstring). With the shoulder width
    W and the hip-to-shoulder midpoint length H of the subject, the fractions of the
    line M_h -> M_s are f_n = 1 - 0.205 W / H and f_p = 0.277 W / H; in the image both
    offsets shorten with the trunk, so the fractions hold in every frame (orthographic
    projection keeps ratios along a line). W and H are read off the video as the link
    lengths are (§4.1): the ``percentile`` of their projected lengths over the frames
    that see both shoulders and both hips.

    Parameters
    ----------
    pixels : (T, K, 2) float
        One person's canonical keypoints over a take (px), NaN where missing.
    joint_names : sequence of str
    percentile : float
        High percentile of the projected lengths taken as seen parallel to the image (90,
        as `mocapkit.tracking.mono.lengths.estimate_link_lengths`).

    Returns
    -------
    (f_n, f_p) : tuple of float
        ``(NECK_FRACTION, PELVIS_FRACTION)`` when no frame sees both shoulders and both
        hips, or when W / H would put the neck at or below the pelvis.
    """
    px = np.asarray(pixels, dtype=float)
    if px.ndim != 3 or px.shape[1:] != (len(joint_names), 2):
        raise ShapeError(
            f"trunk_fractions: expected (T, {len(joint_names)}, 2) keypoints, found {px.shape}"
        )
    if not 0 < percentile <= 100:
        raise ConfigError(f"trunk_fractions: percentile: expected (0, 100], found {percentile}")
    m_s, m_h, across = _trunk_points(px, joint_names)
    w = np.linalg.norm(across, axis=-1)
    h = np.linalg.norm(m_s - m_h, axis=-1)
    ok = np.isfinite(w) & np.isfinite(h) & (h > 0)
    if not ok.any():
        return NECK_FRACTION, PELVIS_FRACTION
    ratio = float(np.percentile(w[ok], percentile) / np.percentile(h[ok], percentile))
    f_n = 1.0 - NECK_BELOW_SHOULDERS * ratio
    f_p = PELVIS_ABOVE_HIPS * ratio
    if not f_p < f_n:
        return NECK_FRACTION, PELVIS_FRACTION
    return f_n, f_p


@contextmanager
def _quiet_nanmean() -> Iterator[None]:
    """Silence numpy's all-NaN slice warning (an unseen face is a normal case)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=RuntimeWarning)
        yield


def read_openpose_folder(
    folder: str | os.PathLike[str],
    time_s: ArrayLike,
    min_confidence: float = MIN_CONFIDENCE,
    start_px: tuple[float, float] | None = None,
    fractions: tuple[float, float] | None = None,
) -> Keypoints:
    """Canonical keypoints of the followed person in an OpenPose JSON folder.

    Parameters
    ----------
    folder : path-like
        One JSON file per frame.
    time_s : (T,) float
        Frame times (the video's); T must equal the number of files.
    min_confidence : float
        Points below this confidence are missing.
    start_px : (x, y), optional
        Follow the person at this image point of the first frame with anyone (default:
        the largest; `mocapkit.cues.follow.PersonFollower`).
    fractions : (f_n, f_p), optional
        Places of the neck and pelvis on the hip-to-shoulder midpoint line; default: the
        followed person's own over the take (`trunk_fractions`).
    """
    files = openpose_files(folder)
    t = np.asarray(time_s, dtype=float)
    if t.shape != (len(files),):
        raise SessionError(
            f"{folder}: expected one JSON file per video frame ({t.shape[0]} frames), found "
            f"{len(files)} files"
        )
    follower = PersonFollower(start_px=start_px)
    px = np.full((len(files), len(MAPPED_JOINTS), 2), np.nan)
    layout_seen = ""
    people_seen = 0
    for i, f in enumerate(files):
        layout, people = read_openpose_frame(f)
        if layout and layout_seen and layout != layout_seen:
            raise FormatError(f"{f}: {layout} keypoints in a folder of {layout_seen} files")
        layout_seen = layout_seen or layout
        people_seen += people.shape[0]
        pick = follower.choose(i, [seen_points(p, min_confidence) for p in people])
        if pick is not None:
            px[i] = to_canonical(people[pick : pick + 1], layout, min_confidence)[0]
    if not np.isfinite(px).any():
        raise SessionError(
            f"{folder}: expected a person's keypoints, found "
            + (
                f"nobody detected in any of its {len(files)} OpenPose files"
                if people_seen == 0
                else f"no confident keypoints (confidence >= {min_confidence:g}) in any of its "
                f"{len(files)} OpenPose files"
            )
        )
    if fractions is None:
        fractions = trunk_fractions(px, MAPPED_JOINTS)
    px = place_trunk_joints(px, MAPPED_JOINTS, fractions)
    return Keypoints(
        t,
        MAPPED_JOINTS,
        px,
        f"{folder} (OpenPose {layout_seen or 'empty'}; neck and pelvis at "
        f"{fractions[0]:.3f} and {fractions[1]:.3f} of the hip-to-shoulder line)",
        REBUILT_JOINTS,
    )


def write_openpose_frame(
    path: str | os.PathLike[str], people: Sequence[ArrayLike], layout: str = "BODY_25"
) -> None:
    """Write one frame's people (each (J, 3): x, y, confidence) as OpenPose JSON (atomic)."""
    from mocapkit.io.atomic import atomic_write

    if layout not in LAYOUTS_BY_NAME:
        raise FormatError(f"OpenPose layout: expected BODY_25 or COCO-18, found {layout!r}")
    n = len(LAYOUTS_BY_NAME[layout])
    doc_people = []
    for i, person in enumerate(people):
        a = np.asarray(person, dtype=float)
        if a.shape != (n, 3):
            raise ShapeError(
                f"write_openpose_frame: person {i}: expected ({n}, 3), found {a.shape}"
            )
        a = np.where(np.isfinite(a), a, 0.0)
        doc_people.append({"person_id": [-1], "pose_keypoints_2d": [float(v) for v in a.ravel()]})
    with atomic_write(path, "w") as fh:
        json.dump({"version": 1.3, "people": doc_people}, fh)


def openpose_from_canonical(
    pixels: ArrayLike,
    joint_names: Sequence[str],
    layout: str = "BODY_25",
    ear_offset_px: float = 8.0,
) -> FloatArray:
    """Detector-style keypoints (T, J, 3) made from canonical ones (T, K, 2), for tests.

    The inverse of `to_canonical` where it can be: shoulders, elbows, wrists, hips, knees,
    ankles copied; "Neck" and "MidHip" the shoulder and hip midpoints; the ears
    ``ear_offset_px`` either side of the head point (so their midpoint is the head), eyes
    and nose in front of it. The canonical neck and pelvis are not used (a detector has
    none). Confidence 0.9 where seen, 0 where missing.
    """
    if layout not in LAYOUTS_BY_NAME:
        raise FormatError(f"OpenPose layout: expected BODY_25 or COCO-18, found {layout!r}")
    names = LAYOUTS_BY_NAME[layout]
    px = np.asarray(pixels, dtype=float)
    jn = list(joint_names)
    if px.ndim != 3 or px.shape[1:] != (len(jn), 2):
        raise ShapeError(f"openpose_from_canonical: expected (T, {len(jn)}, 2), found {px.shape}")

    def can(name: str) -> FloatArray:
        return px[:, jn.index(name)] if name in jn else np.full((px.shape[0], 2), np.nan)

    out = np.full((px.shape[0], len(names), 2), np.nan)
    for joint, det in DIRECT.items():
        out[:, names.index(det)] = can(joint)
    head = can("head")
    off = np.array([ear_offset_px, 0.0])
    out[:, names.index("LEar")] = head + off
    out[:, names.index("REar")] = head - off
    down = np.array([0.0, ear_offset_px])
    out[:, names.index("LEye")] = head + 0.5 * off + 0.3 * down
    out[:, names.index("REye")] = head - 0.5 * off + 0.3 * down
    out[:, names.index("Nose")] = head + 0.6 * down
    out[:, names.index("Neck")] = 0.5 * (can("left_shoulder") + can("right_shoulder"))
    if "MidHip" in names:
        out[:, names.index("MidHip")] = 0.5 * (can("left_hip") + can("right_hip"))
    conf = np.where(np.isfinite(out).all(axis=-1), 0.9, 0.0)
    return np.concatenate([np.where(np.isfinite(out), out, 0.0), conf[..., None]], axis=-1)
