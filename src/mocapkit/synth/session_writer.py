"""Rendering a complete synthetic session (video, markers, keypoints, truth) from a motion.

Pipeline of `synthesize_session`:

1. Load the motion (a BVH/ASF-AMC file via `mocapkit.io.motion_files.read_motion`, or a
   ``builtin:NAME`` procedural motion) and optionally scale its own skeleton to a stature.
2. Place it: the whole clip is lifted so that its lowest joint is 30 mm above the floor
   (z = 0, roughly a shoe sole under the toe joint), and the excerpt's start is recentred
   horizontally so that the pelvis is at the world origin at time 0. The subject then
   stays in view at the start; clips that travel may leave the view later (keypoints are
   NaN there).
3. Cameras of the chosen rig are placed in front of the subject's initial facing direction,
   moved back along their axes where the subject would come closer than 1 m
   (`keep_cameras_away`).
4. Per video frame (jittered times) the fleshed-out body is drawn into each camera over
   a seeded room, with motion blur, lens distortion, lighting and sensor noise.
5. Markers (head on glasses, hands on hand-held objects, elbow reference markers) are
   sampled at their own jittered rate with noise and drop-outs; truth and keypoints are
   sampled at the video frame times.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, MocapError, SessionError, ShapeError
from mocapkit.io.atomic import atomic_folder, remove_stale_temporaries
from mocapkit.io.motion import Motion
from mocapkit.io.session import write_session_json
from mocapkit.io.session_csv import write_keypoints_csv, write_timestamps_csv
from mocapkit.io.truth import Truth
from mocapkit.progress import Progress
from mocapkit.skeleton.model import PRISMATIC, TRUNK_SEGMENTS
from mocapkit.skeleton.scaling import (
    scale_skeleton,
    segment_lengths_mm,
    segment_vectors_mm,
    standing_height_mm,
)
from mocapkit.synth.options import FPS_RANGE, IMAGE_SIDE_RANGE_PX, MARKER_RATE_RANGE_HZ
from mocapkit.synth.realism import (
    RealismOptions,
    corrupt_markers,
    finish_frame,
    jittered_times,
    lighting_field,
    render_background,
)
from mocapkit.synth.render import (
    MARKER_NAMES,
    MARKER_SET_MEMBERS,
    Appearance,
    CameraRenderer,
    build_body,
    costume_sleeve,
    declared_marker_offsets,
    interpolate_tracks,
)
from mocapkit.synth.rigs import make_rig

FloatArray = NDArray[np.float64]
BUILTIN_PREFIX = "builtin:"
#: Height of the lowest joint of a clip above the floor after placement (mm).
FLOOR_CLEARANCE_MM = 30.0
#: Marker sets of synthetic sessions (members: `MARKER_SET_MEMBERS`).
TRACKER_SETS = ("head", "left_hand", "right_hand")
REFERENCE_MARKERS = ("left_elbow_ref", "right_elbow_ref")
VIDEO_FORMATS = ("mp4", "png")


@dataclass(frozen=True)
class SynthOptions:
    """Options of `synthesize_session` (see ``mocapkit synth --help``)."""

    rig: str = "mono"
    start_s: float = 0.0
    seconds: float | None = 5.0
    seed: int = 0
    height_mm: float | None = None
    asf: str | None = None
    fps: float = 30.0
    marker_rate_hz: float = 120.0
    image_size: tuple[int, int] = (640, 480)
    #: Shirt sleeves (`mocapkit.synth.render.SLEEVES`); None: the costume's own.
    sleeve: str | None = None
    #: Clothing (`mocapkit.synth.render.COSTUMES`): ``everyday`` or ``paper``.
    costume: str = "everyday"
    shirt_colour: str | None = None
    video_format: str = "mp4"
    overwrite: bool = False
    realism: RealismOptions = field(default_factory=RealismOptions)
    #: ``(start, duration)`` in s of the excerpt during which every view is blank
    #: (black frames, keypoints NaN): a loss of sight, for testing recovery.
    blackout_s: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        costume_sleeve(self.costume, self.sleeve)
        if self.blackout_s is not None:
            b0, bd = self.blackout_s
            if not (np.isfinite(b0) and np.isfinite(bd) and b0 >= 0 and bd > 0):
                raise ConfigError(
                    f"--blackout-s: expected START,DURATION with START >= 0 s and DURATION > 0 s, "
                    f"found {self.blackout_s}"
                )
        if not (np.isfinite(self.start_s) and self.start_s >= 0):
            raise ConfigError(f"--start-s: expected a time >= 0 s, found {self.start_s}")
        if self.seconds is not None and not (np.isfinite(self.seconds) and self.seconds > 0):
            raise ConfigError(f"--seconds: expected a positive duration, found {self.seconds}")
        if not (FPS_RANGE[0] <= self.fps <= FPS_RANGE[1]):
            raise ConfigError(f"--fps: expected 1-1000 frames per second, found {self.fps}")
        if not (MARKER_RATE_RANGE_HZ[0] <= self.marker_rate_hz <= MARKER_RATE_RANGE_HZ[1]):
            raise ConfigError(f"--marker-rate: expected 1-2000 Hz, found {self.marker_rate_hz}")
        w, h = self.image_size
        lo, hi = IMAGE_SIDE_RANGE_PX
        if not (lo <= w <= hi and lo <= h <= hi):
            raise ConfigError(f"--size: expected WxH between 32 and 8192 px, found {w}x{h}")
        if self.video_format not in VIDEO_FORMATS:
            raise ConfigError(
                f"video format: expected one of {', '.join(VIDEO_FORMATS)}, "
                f"found {self.video_format!r}"
            )


@dataclass(frozen=True)
class SynthSummary:
    """What `synthesize_session` wrote."""

    out_dir: Path
    motion: str
    cameras: tuple[str, ...]
    n_frames: int
    n_marker_samples: int
    duration_s: float
    render_s: float
    notes: tuple[str, ...] = ()

    def text(self) -> str:
        """A short human-readable report."""
        lines = [
            f"session written to {self.out_dir}",
            f"  motion: {self.motion}",
            f"  cameras: {', '.join(self.cameras)}; {self.n_frames} frames over "
            f"{self.duration_s:.2f} s; {self.n_marker_samples} marker samples",
            f"  rendering took {self.render_s:.1f} s",
        ]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


#: Nearest a joint may come to a synthetic camera (depth along its optical axis, mm).
MIN_CAMERA_DEPTH_MM = 1000.0


def keep_cameras_away(
    cameras: list[Camera], joints_in_world_mm: NDArray[np.float64]
) -> tuple[list[Camera], float]:
    """Move a rig back along its optical axes until no joint comes closer than 1 m.

    The rig is placed in front of the subject's start (`mocapkit.synth.rigs.make_rig`);
    a subject who walks or hops towards it would otherwise come up to, and through, the
    lens (one CMU clip in its first 8 s: the pelvis ends 0.1 m behind the camera plane),
    which no recording would show. Every camera moves by the same distance along its own
    axis, so a stereo pair keeps its baseline and parallel axes.

    Parameters
    ----------
    cameras : list of Camera
    joints_in_world_mm : ndarray, shape (T, J, 3)
        The excerpt's joints, world mm (NaN allowed).

    Returns
    -------
    cameras : list of Camera
        Moved copies (the same objects when none had to move).
    moved_mm : float
        How far they were moved back (0 when not at all).
    """
    pts = np.asarray(joints_in_world_mm, dtype=float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if pts.size == 0:
        return cameras, 0.0
    nearest = min(float(np.min(c.to_camera(pts)[:, 2])) for c in cameras)
    moved = max(0.0, MIN_CAMERA_DEPTH_MM - nearest)
    if moved == 0.0:
        return cameras, 0.0
    out = []
    for c in cameras:
        camera_from_world = c.camera_from_world.copy()
        camera_from_world[2, 3] += moved  # the camera steps back along its own axis
        out.append(replace(c, camera_from_world=camera_from_world))
    return out, moved


def load_motion_source(spec: str, asf: str | None = None, duration_s: float = 0.0) -> Motion:
    """A motion from a file path (BVH, AMC) or ``builtin:NAME``.

    A built-in motion lasts 20 s, or ``duration_s`` where that is longer (a file's
    motion lasts as long as the file).
    """
    if spec.startswith(BUILTIN_PREFIX):
        from mocapkit.synth.builtin_motions import DEFAULT_DURATION_S, builtin_motion

        length = max(DEFAULT_DURATION_S, float(duration_s))
        return builtin_motion(spec[len(BUILTIN_PREFIX) :], duration_s=length)
    from mocapkit.io.motion_files import read_motion

    return read_motion(spec, asf=asf)


def scale_motion(motion: Motion, height_mm: float) -> Motion:
    """The motion on its own skeleton scaled to a stature (root translations scale too)."""
    factor = height_mm / standing_height_mm(motion.skeleton)
    skel = scale_skeleton(motion.skeleton, height_mm=height_mm)
    q = np.array(motion.q, dtype=float)
    q[:, skel.dof_kind == PRISMATIC] *= factor
    return Motion.from_q(skel, motion.time_s, q, f"{motion.source} scaled to {height_mm:.0f} mm")


def _check_out(out: Path, overwrite: bool) -> None:
    """Refuse an output that is a file, or a non-empty folder unless it is a session to replace."""
    if out.exists() and not out.is_dir():
        raise SessionError(f"{out}: output exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise SessionError(
                f"{out}: output folder is not empty (pass --overwrite to replace a session)"
            )
        if not (out / "session.json").is_file():
            raise SessionError(f"{out}: refusing to overwrite a folder that holds no session.json")


class _VideoOut:
    """Writes one camera's frames as mp4v video or a PNG folder, and checks the result."""

    def __init__(
        self, folder: Path, camera: str, fmt: str, fps: float, size: tuple[int, int]
    ) -> None:
        self.fmt = fmt
        self.count = 0
        if fmt == "mp4":
            self.path = folder / f"{camera}.mp4"
            self.tmp = folder / f".{camera}.tmp.mp4"
            fourcc = cv2.VideoWriter.fourcc(*"mp4v")
            self.writer = cv2.VideoWriter(str(self.tmp), fourcc, float(fps), size)
            if not self.writer.isOpened():
                raise SessionError(f"{self.path}: OpenCV cannot open an mp4v video writer")
        else:
            self.path = folder / camera
            self.path.mkdir(parents=True, exist_ok=True)

    def write(self, image: NDArray[np.uint8]) -> None:
        if self.fmt == "mp4":
            self.writer.write(image)
        elif not cv2.imwrite(str(self.path / f"{self.count:06d}.png"), image):
            raise SessionError(f"{self.path}: cannot write frame {self.count}")
        self.count += 1

    def close(self) -> None:
        if self.fmt != "mp4":
            return
        self.writer.release()
        cap = cv2.VideoCapture(str(self.tmp))
        n = 0
        try:
            while cap.grab():
                n += 1
        finally:
            cap.release()
        if n != self.count:
            raise SessionError(
                f"{self.path}: video reads back {n} frames, expected {self.count}; the OpenCV "
                f"build cannot round-trip mp4v (use the PNG video format)"
            )
        self.tmp.replace(self.path)


def _facing(joints: FloatArray, names: tuple[str, ...]) -> FloatArray:
    """Horizontal facing direction (3,) from shoulders and hips of one frame (K, 3)."""
    idx = {n: i for i, n in enumerate(names)}
    right = np.zeros(3)
    for a, b in (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip")):
        if a in idx and b in idx:
            right += joints[idx[b]] - joints[idx[a]]
    fwd = np.cross(np.array([0.0, 0.0, 1.0]), right)
    n = np.linalg.norm(fwd)
    return fwd / n if n > 1e-6 else np.array([0.0, 1.0, 0.0])


def synthesize_session(
    motion_spec: str, out_dir: str | Path, options: SynthOptions
) -> SynthSummary:
    """Render a synthetic session folder from a motion file or a built-in motion.

    The session is rendered into a temporary folder beside ``out_dir`` and swapped in
    when complete (`mocapkit.io.atomic.atomic_folder`): an interrupted run leaves no
    session that looks complete, and with ``overwrite`` the old session stays whole
    until the new one is.

    Parameters
    ----------
    motion_spec : str
        Path of a BVH or AMC file, or ``builtin:table-tennis|squat|wave``.
    out_dir : path-like
        Session folder to create (see `mocapkit.io.session` for the layout).
    options : SynthOptions

    Returns
    -------
    SynthSummary
    """
    final = Path(out_dir)
    _check_out(final, options.overwrite)
    remove_stale_temporaries(final.parent, final.name)
    with atomic_folder(final) as tmp:
        summary = _render_session(motion_spec, tmp, final.name, options)
    return replace(summary, out_dir=final)


def _render_session(motion_spec: str, out: Path, label: str, options: SynthOptions) -> SynthSummary:
    """`synthesize_session` into the (temporary) folder ``out``; ``label`` names it."""
    t_start = time.perf_counter()
    opts = options
    root_rng = np.random.SeedSequence(int(opts.seed))
    seeds = root_rng.spawn(6)
    rng_look, rng_room, rng_light, rng_time, rng_markers, rng_noise = (
        np.random.default_rng(s) for s in seeds
    )
    needed_s = opts.start_s + (opts.seconds if opts.seconds is not None else 0.0)
    motion = load_motion_source(motion_spec, opts.asf, duration_s=needed_s)
    notes: list[str] = []
    if opts.height_mm is not None:
        motion = scale_motion(motion, opts.height_mm)
    if np.any(~np.isfinite(motion.q)):
        raise ShapeError(
            f"{motion.source}: the motion has frames without a pose (NaN); cannot render"
        )
    t_m = np.asarray(motion.time_s, dtype=float)
    if t_m.shape[0] < 2:
        raise ShapeError(f"{motion.source}: expected at least 2 frames, found {t_m.shape[0]}")
    clip_end = float(t_m[-1])
    if opts.start_s >= clip_end:
        raise ConfigError(
            f"--start-s {opts.start_s}: the clip {motion.source} lasts {clip_end:.3f} s"
        )
    end = clip_end if opts.seconds is None else opts.start_s + opts.seconds
    if end > clip_end + 1e-9:
        notes.append(f"clip ends at {clip_end:.2f} s; excerpt shortened from {opts.seconds} s")
        end = clip_end
    duration = end - opts.start_s
    i0 = max(0, int(np.searchsorted(t_m, opts.start_s, side="right")) - 2)
    i1 = min(len(t_m), int(np.searchsorted(t_m, end, side="left")) + 2)
    t_local = t_m[i0:i1] - opts.start_s

    # -------------------------------------------------------- placement
    joints_all = np.asarray(motion.joints_mm)
    from mocapkit.skeleton.kinematics import joint_positions

    lowest = float(np.min(joint_positions(motion.skeleton, motion.q)[..., 2]))
    names = motion.joint_names
    start_joints = interpolate_tracks(t_m, joints_all, np.array([opts.start_s]))[0]
    pelvis0 = start_joints[names.index("pelvis")]
    shift = np.array([-pelvis0[0], -pelvis0[1], FLOOR_CLEARANCE_MM - lowest])
    fwd = _facing(start_joints, names)
    shoulders = [
        start_joints[names.index(n)][2] for n in ("left_shoulder", "right_shoulder") if n in names
    ]
    chest = (float(np.mean(shoulders)) + shift[2] - 120.0) if shoulders else 1300.0

    appearance = Appearance.random(rng_look, opts.shirt_colour, opts.sleeve, opts.costume)
    body = build_body(motion.skeleton, t_local, np.asarray(motion.q)[i0:i1], appearance, shift)
    cameras = make_rig(opts.rig, np.zeros(3), fwd, chest, opts.image_size, rng_look)
    cameras, pulled_back_mm = keep_cameras_away(cameras, joints_all[i0:i1] + shift)
    if pulled_back_mm > 0:
        notes.append(
            f"the subject comes towards the cameras; they were moved back "
            f"{pulled_back_mm:.0f} mm so that no joint comes closer than "
            f"{MIN_CAMERA_DEPTH_MM:.0f} mm"
        )

    # -------------------------------------------------------- times
    n_video = int(np.floor(duration * opts.fps + 1e-9)) + 1
    t_video = np.clip(
        jittered_times(n_video, opts.fps, opts.realism.video_jitter_s, rng_time), 0.0, duration
    )
    t_video = np.maximum.accumulate(t_video)
    if np.any(np.diff(t_video) <= 0):
        raise ConfigError("video time stamps collapsed; increase --seconds or lower the jitter")
    dt_m = 1.0 / opts.marker_rate_hz
    # the marker system runs independently of the camera and is already streaming when
    # the first video frame is taken: its first sample lies before t = 0 (by 0.05-0.75 of
    # its interval after jitter), so every video frame has a newest marker sample
    start_m = -float(rng_time.uniform(0.3 * dt_m, 0.5 * dt_m))
    # ... and every video frame up to the last one has a sample within one interval
    n_mark = int(np.floor((duration - start_m) * opts.marker_rate_hz + 1e-9)) + 1
    t_mark = jittered_times(
        n_mark,
        opts.marker_rate_hz,
        opts.realism.marker_jitter_s,
        rng_time,
        start_s=start_m,
    )

    # -------------------------------------------------------- static data
    from mocapkit.io.cameras import write_cameras
    from mocapkit.io.marker_csv import write_markers_csv

    write_cameras(out / "cameras.json", cameras)
    joints_local = joints_all[i0:i1] + shift
    truth = Truth(
        t_video,
        names,
        interpolate_tracks(t_local, joints_local, t_video),
        MARKER_NAMES,
        body.markers_at(t_video),
    )
    truth.save(out / "truth.npz")
    markers = corrupt_markers(
        body.markers_at(t_mark), opts.marker_rate_hz, opts.realism, rng_markers
    )
    write_markers_csv(out / "markers.csv", t_mark, MARKER_NAMES, markers)
    blank = np.zeros(t_video.shape[0], dtype=bool)
    if opts.blackout_s is not None:
        b0, bd = opts.blackout_s
        blank = (t_video >= b0) & (t_video < b0 + bd)
    for cam in cameras:
        px = cam.project(truth.joints_mm)
        px[~cam.in_image(px)] = np.nan
        px[blank] = np.nan  # a blank view sees nothing
        write_keypoints_csv(out / "keypoints" / f"{cam.name}.csv", t_video, names, px)
    vdir = out / "video"
    vdir.mkdir(parents=True, exist_ok=True)
    jittered = opts.realism.video_jitter_s > 0
    if jittered:
        for cam in cameras:
            write_timestamps_csv(vdir / f"{cam.name}.timestamps.csv", t_video)
    height = standing_height_mm(motion.skeleton)
    info = {
        "subject": {
            "height_mm": round(float(np.clip(height, 500, 2800)), 1),
            # measured on the motion's own skeleton, as a lab measures its subject
            "bone_lengths_mm": {
                k: round(v, 1) for k, v in segment_lengths_mm(motion.skeleton).items()
            },
            # trunk geometry of the standing subject (a static trial): where the
            # shoulders and hips sit relative to the neck base and the pelvis
            "segment_vectors_mm": {
                k: [round(float(x), 1) for x in v]
                for k, v in segment_vectors_mm(motion.skeleton).items()
                if k in TRUNK_SEGMENTS
            },
        },
        "marker_offsets_mm": declared_marker_offsets(motion.skeleton),
        "cameras": "cameras.json",
        "marker_sets": {s: list(MARKER_SET_MEMBERS[s]) for s in TRACKER_SETS},
        "reference_markers": list(REFERENCE_MARKERS),
        "rates": {"video_hz": opts.fps, "markers_hz": opts.marker_rate_hz},
        "synthetic": {
            "motion": motion_spec,
            "motion_source": motion.source,
            "start_s": opts.start_s,
            "seconds": duration,
            "seed": opts.seed,
            "rig": opts.rig,
            "shift_mm": [round(float(v), 3) for v in shift],
            "sleeve": appearance.sleeve,
            "costume": opts.costume,
            "blackout_s": None if opts.blackout_s is None else list(opts.blackout_s),
            "realism": asdict(opts.realism),
            "notes": notes,
        },
    }
    write_session_json(out / "session.json", json.loads(json.dumps(info)))

    # -------------------------------------------------------- video
    renderers = [CameraRenderer(c) for c in cameras]
    backgrounds = []
    lights = []
    room_state = rng_room.bit_generator.state
    for r in renderers:
        rng_room.bit_generator.state = room_state  # the same room in every view
        backgrounds.append(
            render_background(r, np.zeros(3), fwd, opts.realism.background, rng_room)
        )
        lights.append(lighting_field(opts.image_size, rng_light))
    exposure = opts.realism.blur / opts.fps
    offsets = [0.0] if exposure <= 0 else [-0.25 * exposure, 0.25 * exposure]
    sub_times = (t_video[:, None] + np.array(offsets)[None, :]).ravel()
    points = body.points_at(sub_times).reshape(n_video, len(offsets), -1, 3)
    writers = [
        _VideoOut(vdir, c.name, opts.video_format, opts.fps, opts.image_size) for c in cameras
    ]
    try:
        with Progress(n_video, f"synth {label}") as progress:
            for k in range(n_video):
                for r, bg, light, w in zip(renderers, backgrounds, lights, writers):
                    canvas = bg.copy()
                    r.draw_body(canvas, body.primitives, points[k, 0])
                    if len(offsets) > 1:
                        second = bg.copy()
                        r.draw_body(second, body.primitives, points[k, 1])
                        canvas = np.asarray(
                            cv2.addWeighted(canvas, 0.5, second, 0.5, 0.0), dtype=np.uint8
                        )
                    image = finish_frame(r.warp(canvas), light, opts.realism.noise, rng_noise)
                    if blank[k]:
                        image = np.zeros_like(image)
                    w.write(image)
                progress.update()
    finally:
        errors: list[MocapError] = []
        for w in writers:
            try:
                w.close()
            except MocapError as exc:  # report every camera, not just the first
                errors.append(exc)
        if errors:
            raise errors[0]
    return SynthSummary(
        out_dir=out,
        motion=motion.source,
        cameras=tuple(c.name for c in cameras),
        n_frames=n_video,
        n_marker_samples=n_mark,
        duration_s=duration,
        render_s=time.perf_counter() - t_start,
        notes=tuple(notes),
    )
