"""Accuracy of a tracked motion against truth: MPJPE, PA-MPJPE, elbow error, jitter, coverage.

Samples are matched by time stamp, never by frame index: each truth frame takes the
nearest result sample if it lies within half the truth's frame interval (median spacing);
coverage is the share of (truth frame, joint) pairs with an estimate, so a truth frame
without a match, or a joint that is NaN (an arm released while its hand was unseen),
counts against it; per joint too.
Errors are Euclidean distances (mm) averaged over the matched frames where both sides
have the joint. PA-MPJPE aligns each result frame to the truth by the similarity
transform (rotation, translation and scale) minimising the squared error (Umeyama 1991).
The elbow error is the mean of both elbows' mean errors, the hybrid paper's measure
(Zhang et al. 2011, §6). Jitter is the mean magnitude of the second time derivative
(mm/s²) over consecutive matched frames, reported beside the truth's own on the same frames.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, FormatError, SessionError, ShapeError, unknown_name
from mocapkit.skeleton.model import CANONICAL_JOINTS, UPPER_BODY_JOINTS

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class EvalReport:
    """Evaluation figures (mm, mm/s², fraction); NaN where nothing could be compared."""

    per_joint_mm: dict[str, float]
    mpjpe_mm: float
    pa_mpjpe_mm: float
    elbow_mm: float
    jitter_mm_s2: float
    truth_jitter_mm_s2: float
    coverage: float
    n_truth_frames: int
    n_matched_frames: int
    joints: tuple[str, ...]
    per_joint_coverage: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready dict (NaN becomes None)."""

        def clean(v: object) -> object:
            if isinstance(v, float) and not np.isfinite(v):
                return None
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, tuple):
                return list(v)
            return v

        return {k: clean(v) for k, v in asdict(self).items()}

    def to_json(self) -> str:
        """The report as JSON text."""
        return json.dumps(self.to_dict(), indent=2)

    def table(self) -> str:
        """A plain-text table."""

        def f(v: float) -> str:
            return "n/a" if not np.isfinite(v) else f"{v:.1f}"

        lines = [f"{'joint':<16}{'error_mm':>10}{'coverage':>10}"]
        lines += [
            f"{n:<16}{f(v):>10}{self.per_joint_coverage.get(n, float('nan')):>10.3f}"
            for n, v in self.per_joint_mm.items()
        ]
        lines += [
            "",
            f"{'mpjpe_mm':<22}{f(self.mpjpe_mm):>10}",
            f"{'pa_mpjpe_mm':<22}{f(self.pa_mpjpe_mm):>10}",
            f"{'elbow_mm':<22}{f(self.elbow_mm):>10}",
            f"{'jitter_mm_s2':<22}{f(self.jitter_mm_s2):>10}"
            f"   (truth {f(self.truth_jitter_mm_s2)})",
            f"{'coverage':<22}{self.coverage:>10.3f}   "
            f"(joints estimated; {self.n_matched_frames}/{self.n_truth_frames} truth frames "
            "with a pose)",
        ]
        return "\n".join(lines)


def match_by_time(truth_time_s: FloatArray, result_time_s: FloatArray) -> NDArray[np.int64]:
    """For each truth time, the index of the nearest result sample within half a truth interval.

    Returns
    -------
    (T,) int array
        Result index per truth frame, -1 where none lies close enough.
    """
    tt = np.asarray(truth_time_s, dtype=float)
    rt = np.asarray(result_time_s, dtype=float)
    out = np.full(tt.shape[0], -1, dtype=np.int64)
    if rt.shape[0] == 0 or tt.shape[0] == 0:
        return out
    order = np.argsort(rt, kind="stable")
    rs = rt[order]
    tol = 0.5 * float(np.median(np.diff(tt))) if tt.shape[0] > 1 else np.inf
    j = np.clip(np.searchsorted(rs, tt), 1, max(rs.shape[0] - 1, 1))
    if rs.shape[0] == 1:
        best = np.zeros_like(j)
    else:
        left = rs[j - 1]
        right = rs[j]
        best = np.where(np.abs(tt - left) <= np.abs(right - tt), j - 1, j)
    ok = np.abs(rs[best] - tt) <= tol + 1e-12
    out[ok] = order[best[ok]]
    return out


def similarity_align(source: FloatArray, target: FloatArray) -> FloatArray:
    """Align points (K, 3) to target (K, 3) by the best rotation, translation and scale.

    Umeyama (1991): centre both, SVD of the cross-covariance, reflection-corrected.
    """
    mu_s = source.mean(axis=0)
    mu_t = target.mean(axis=0)
    xs = source - mu_s
    xt = target - mu_t
    var_s = float(np.sum(xs**2)) / source.shape[0]
    if var_s <= 0:
        return np.broadcast_to(mu_t, source.shape).copy()
    cov = xt.T @ xs / source.shape[0]
    u, d, vt = np.linalg.svd(cov)
    s = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2] = -1.0
    rot = u @ np.diag(s) @ vt
    scale = float(np.sum(d * s)) / var_s
    return scale * xs @ rot.T + mu_t


def best_swivel_elbow(
    shoulder_mm: ArrayLike, elbow_mm: ArrayLike, wrist_mm: ArrayLike, target_mm: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """The elbow turned about its shoulder-wrist axis to the point nearest a target.

    Splits an elbow error into what the arm's swivel costs and what it does not: the
    turned elbow keeps its distances to the shoulder and the wrist (the same segment
    lengths and hand placement), so its distance to ``target`` (an elbow marker) is the
    error no swivel could remove (the *best-swivel floor*), and ``turn_rad`` is how far
    the tracked swivel is from it. With positions-only hand sets nothing but the IK's
    relaxed-pose task chooses the swivel (docs/design-notes/hybrid.md, "Elbow error split per
    frame").

    Parameters
    ----------
    shoulder_mm, elbow_mm, wrist_mm, target_mm : array_like, shape (T, 3) or (3,)
        Tracked shoulder, elbow and wrist, and the target (mm, one frame).

    Returns
    -------
    elbow : ndarray, shape like ``elbow_mm``
        The turned elbow (mm); NaN where any input is NaN, the arm is straight, or the
        target lies on the shoulder-wrist axis.
    turn_rad : ndarray, shape (T,) or ()
        Signed turn (rad) from ``elbow_mm`` to ``elbow`` about the shoulder-to-wrist
        axis (right-handed), in (-pi, pi].

    Raises
    ------
    ShapeError
        The four inputs differ in shape, or their last axis is not 3.
    """
    arrays = [np.asarray(a, dtype=float) for a in (shoulder_mm, elbow_mm, wrist_mm, target_mm)]
    shapes = {a.shape for a in arrays}
    if len(shapes) != 1 or arrays[0].shape[-1:] != (3,):
        raise ShapeError(
            "best_swivel_elbow: expected shoulder, elbow, wrist and target of one shape "
            f"(T, 3) or (3,), found {[a.shape for a in arrays]}"
        )
    s, e, w, t = arrays
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = (w - s) / np.linalg.norm(w - s, axis=-1, keepdims=True)
        centre = s + np.sum((e - s) * axis, axis=-1, keepdims=True) * axis
        radial = e - centre
        radius = np.linalg.norm(radial, axis=-1, keepdims=True)
        toward = t - centre
        toward = toward - np.sum(toward * axis, axis=-1, keepdims=True) * axis
        toward_len = np.linalg.norm(toward, axis=-1, keepdims=True)
        degenerate = (radius < 1e-9) | (toward_len < 1e-9)
        best = np.where(degenerate, np.nan, centre + radius * toward / toward_len)
        sin = np.sum(np.cross(radial, best - centre) * axis, axis=-1)
        cos = np.sum(radial * (best - centre), axis=-1)
    return best, np.asarray(np.arctan2(sin, cos), dtype=float)


def _second_difference(t: FloatArray, x: FloatArray) -> FloatArray:
    """Second derivative at interior samples (N-2, ...) for uneven times t (N,)."""
    h1 = (t[1:-1] - t[:-2]).reshape(-1, *([1] * (x.ndim - 1)))
    h2 = (t[2:] - t[1:-1]).reshape(-1, *([1] * (x.ndim - 1)))
    return 2.0 * ((x[2:] - x[1:-1]) / h2 - (x[1:-1] - x[:-2]) / h1) / (h1 + h2)


def _jitter(t: FloatArray, x: FloatArray, valid: NDArray[np.bool_], dt: float) -> float:
    """Mean |second derivative| over runs of consecutive frames where x is valid."""
    vals: list[FloatArray] = []
    n = t.shape[0]
    start = 0
    while start < n:
        if not valid[start]:
            start += 1
            continue
        stop = start
        while stop + 1 < n and valid[stop + 1] and (t[stop + 1] - t[stop]) <= 1.5 * dt:
            stop += 1
        if stop - start >= 2:
            acc = _second_difference(t[start : stop + 1], x[start : stop + 1])
            mag = np.linalg.norm(acc, axis=-1)
            vals.append(mag[np.isfinite(mag)])
        start = stop + 1
    allv = np.concatenate(vals) if vals else np.zeros(0)
    return float(allv.mean()) if allv.size else float("nan")


def evaluate_joints(
    result_time_s: ArrayLike,
    result_names: tuple[str, ...] | list[str],
    result_joints_mm: ArrayLike,
    truth_time_s: ArrayLike,
    truth_names: tuple[str, ...] | list[str],
    truth_joints_mm: ArrayLike,
    joints: Sequence[str] | None = None,
) -> EvalReport:
    """Compare result joints with truth joints, matched by time stamp.

    Parameters
    ----------
    result_time_s : (R,) float array
    result_names : sequence of str
        Canonical names of the result's K_r joints.
    result_joints_mm : (R, K_r, 3) float array
        World positions (mm); NaN where the tracker gave no estimate.
    truth_time_s : (T,) float array
    truth_names : sequence of str
    truth_joints_mm : (T, K_t, 3) float array
    joints : sequence of str, optional
        Restrict the comparison to these canonical joints (e.g. `UPPER_BODY_JOINTS`);
        default: every joint both sides have.

    Returns
    -------
    EvalReport
    """
    rt = np.asarray(result_time_s, dtype=float)
    rj = np.asarray(result_joints_mm, dtype=float)
    tt = np.asarray(truth_time_s, dtype=float)
    tj = np.asarray(truth_joints_mm, dtype=float)
    if rj.shape != (rt.shape[0], len(result_names), 3):
        raise ShapeError(
            f"result: expected joints of shape ({rt.shape[0]}, {len(result_names)}, 3), "
            f"found {rj.shape}"
        )
    if tj.shape != (tt.shape[0], len(truth_names), 3):
        raise ShapeError(
            f"truth: expected joints of shape ({tt.shape[0]}, {len(truth_names)}, 3), "
            f"found {tj.shape}"
        )
    if joints is not None:
        unknown = [n for n in joints if n not in CANONICAL_JOINTS]
        if unknown:
            raise unknown_name("canonical joint", unknown[0], CANONICAL_JOINTS, "joints")
    common = tuple(n for n in truth_names if n in result_names and (joints is None or n in joints))
    if not common:
        raise ShapeError(
            f"result and truth share no joint: result has {list(result_names)}, truth has "
            f"{list(truth_names)}"
        )
    ti = [list(truth_names).index(n) for n in common]
    ri = [list(result_names).index(n) for n in common]
    match = match_by_time(tt, rt)
    matched = match >= 0
    est = np.full((tt.shape[0], len(common), 3), np.nan)
    est[matched] = rj[match[matched]][:, ri]
    ref = tj[:, ti]
    estimated = matched[:, None] & np.all(np.isfinite(est), axis=-1)  # (T, K)
    has_pose = np.any(estimated, axis=-1)
    err = np.linalg.norm(est - ref, axis=-1)  # (T, K), NaN where missing
    with np.errstate(invalid="ignore"):
        per_joint = {
            n: float(np.nanmean(err[:, k])) if np.any(np.isfinite(err[:, k])) else float("nan")
            for k, n in enumerate(common)
        }
    fin = np.isfinite(err)
    mpjpe = float(err[fin].mean()) if fin.any() else float("nan")
    pa: list[float] = []
    for f in np.flatnonzero(has_pose):
        ok = np.all(np.isfinite(est[f]), axis=-1) & np.all(np.isfinite(ref[f]), axis=-1)
        if ok.sum() >= 3:
            aligned = similarity_align(est[f, ok], ref[f, ok])
            pa.append(float(np.linalg.norm(aligned - ref[f, ok], axis=-1).mean()))
    elbows = [
        per_joint[n]
        for n in ("left_elbow", "right_elbow")
        if n in per_joint and np.isfinite(per_joint[n])
    ]
    dt = float(np.median(np.diff(tt))) if tt.shape[0] > 1 else 1.0
    valid_frames = has_pose & np.all(np.isfinite(est), axis=(1, 2))
    jit = _jitter(tt, est, valid_frames, dt)
    truth_jit = _jitter(tt, ref, valid_frames, dt)
    return EvalReport(
        per_joint_mm=per_joint,
        mpjpe_mm=mpjpe,
        pa_mpjpe_mm=float(np.mean(pa)) if pa else float("nan"),
        elbow_mm=float(np.mean(elbows)) if elbows else float("nan"),
        jitter_mm_s2=jit,
        truth_jitter_mm_s2=truth_jit,
        coverage=float(estimated.mean()) if estimated.size else 0.0,
        n_truth_frames=int(tt.shape[0]),
        n_matched_frames=int(has_pose.sum()),
        joints=common,
        per_joint_coverage={
            n: float(estimated[:, k].mean()) if tt.shape[0] else 0.0 for k, n in enumerate(common)
        },
    )


def joint_subset(spec: str) -> tuple[str, ...] | None:
    """Canonical joints named by ``all`` (None: every shared joint), ``upper`` or a list.

    ``upper`` is the upper body the marker-and-camera trackers estimate from arms and
    head: head, neck, pelvis, shoulders, elbows and wrists.
    """
    if spec == "all":
        return None
    if spec == "upper":
        return UPPER_BODY_JOINTS
    names = tuple(n.strip() for n in spec.split(",") if n.strip())
    if not names:
        raise ConfigError(
            f"--joints: expected 'all', 'upper' or a comma-separated list of canonical "
            f"joints, found {spec!r}"
        )
    for n in names:
        if n not in CANONICAL_JOINTS:
            raise unknown_name(
                "canonical joint", n, (*CANONICAL_JOINTS, "all", "upper"), "--joints"
            )
    return names


def load_result_joints(
    result: str | os.PathLike[str],
) -> tuple[FloatArray, tuple[str, ...], FloatArray]:
    """Time (R,), canonical names and joints (R, K, 3) of a tracker's result.

    ``result`` is a result folder (``motion.npz`` preferred, else ``joints.csv``) or one of
    those files.
    """
    from mocapkit.io.joints_csv import read_joints_csv
    from mocapkit.io.motion_npz import load_motion_npz

    p = Path(result)
    if p.is_dir():
        if (p / "motion.npz").is_file():
            p = p / "motion.npz"
        elif (p / "joints.csv").is_file():
            p = p / "joints.csv"
        else:
            raise SessionError(f"{p}: result folder holds neither motion.npz nor joints.csv")
    if not p.is_file():
        raise SessionError(f"{p}: result not found")
    if p.suffix == ".npz":
        m = load_motion_npz(p)
        return np.asarray(m.time_s), m.joint_names, np.asarray(m.joints_mm)
    if p.suffix == ".csv":
        return read_joints_csv(p)
    raise FormatError(f"{p}: expected a result folder, motion.npz or joints.csv")


def evaluate_result(
    result: str | os.PathLike[str],
    truth_session: str | os.PathLike[str],
    joints: Sequence[str] | None = None,
) -> EvalReport:
    """Evaluate a tracker's result folder against a synthetic session's ``truth.npz``.

    Parameters
    ----------
    result : path-like
        Result folder (or its ``motion.npz`` / ``joints.csv``).
    truth_session : path-like
        Session folder with ``truth.npz`` (or the ``truth.npz`` file itself).
    joints : sequence of str, optional
        Canonical joints to compare (default: all both sides have).
    """
    from mocapkit.io.session import load_session
    from mocapkit.io.truth import load_truth

    rt, rn, rj = load_result_joints(result)
    tp = Path(truth_session)
    if tp.is_file():
        truth = load_truth(tp)
    else:
        session = load_session(tp)
        session.require(truth=True)
        if session.truth is None:  # unreachable after require
            raise SessionError(f"{tp}: no truth.npz")
        truth = session.truth
    return evaluate_joints(
        rt, rn, rj, truth.time_s, truth.joint_names, truth.joints_mm, joints=joints
    )
