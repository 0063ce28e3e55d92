"""Fleshing out a motion file's own skeleton into a clothed body and rasterising it with OpenCV.

The body is built from the skeleton of the motion file itself (never from a tracker's
model): every bone becomes a tapered capsule whose radii come from the bone's role
(upper arm, forearm, hand, thigh, shank, foot, neck), the trunk becomes two convex
hulls (shirt and trousers), the head an ellipsoid with hair and glasses. Roles are found
from the skeleton's canonical map: a joint takes the role of the nearest canonical joint
at or above it (e.g. every joint below ``left_elbow`` and above ``left_wrist`` is forearm).

Rasterisation: each primitive is projected with the ideal (distortion-free) camera into a
canvas larger than the image, drawn far to near (painter's algorithm with one depth key per
primitive, adequate for convex body parts that do not interpenetrate much), then the canvas
is warped by the lens distortion with one `cv2.remap`, so that the image and
`Camera.project` agree.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.projection import camera_arrays, project
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.rotations import matrix_from_axis_angle
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import Skeleton
from mocapkit.synth.options import COSTUMES, SLEEVES

FloatArray = NDArray[np.float64]

CAPSULE = 0
HULL = 1
ELLIPSOID = 2
SPHERE = 3

#: Role of the segment owned by the joint that carries each canonical joint.
ROLE_OF_CANONICAL = {
    "pelvis": "trunk",
    "neck": "neck",
    "head": "head",
    "left_shoulder": "upper_arm",
    "right_shoulder": "upper_arm",
    "left_elbow": "forearm",
    "right_elbow": "forearm",
    "left_wrist": "hand",
    "right_wrist": "hand",
    "left_hip": "thigh",
    "right_hip": "thigh",
    "left_knee": "shank",
    "right_knee": "shank",
    "left_ankle": "foot",
    "right_ankle": "foot",
}

#: Proximal and distal radii (mm) per role: typical adult girths (upper arm 90-100 mm
#: diameter, forearm 60-80 mm, thigh about 140 mm, calf about 100 mm; errata recipe Z).
ROLE_RADII_MM = {
    "upper_arm": (48.0, 40.0),
    "forearm": (38.0, 30.0),
    "hand": (36.0, 30.0),
    "fingers": (22.0, 16.0),
    "thigh": (75.0, 55.0),
    "shank": (52.0, 40.0),
    "foot": (42.0, 36.0),
    "toes": (36.0, 30.0),
    "neck": (55.0, 50.0),
    "clavicle": (55.0, 48.0),
}

#: Head ellipsoid semi-axes (mm): lateral, front-back, vertical.
HEAD_RADII_MM = (78.0, 95.0, 112.0)
#: Offsets of the markers fixed to the body (mm): the head marker sits on glasses in front
#: of the face, each hand marker on a hand-held object, each elbow reference marker on the
#: back of the elbow (olecranon), as the hybrid paper's evaluation marker.
HEAD_MARKER_FORWARD_MM = 100.0
HAND_MARKER_ALONG_MM = 80.0
HAND_MARKER_OUT_MM = 35.0
ELBOW_MARKER_OUT_MM = 45.0
#: The other two markers of each rigid marker set (the hybrid paper's marker sets are
#: several markers on the 3-D glasses and on each hand-held object, Fig. 9): on the
#: glasses' temples (mm in the head frame: right, forward, up), and on the hand-held
#: object 50 mm further along it and 40 mm to its side.
HEAD_TEMPLE_MM = (70.0, 60.0, 0.0)
HAND_OBJECT_TIP_MM = 50.0
HAND_OBJECT_SIDE_MM = 40.0

MARKER_NAMES: tuple[str, ...] = (
    "head",
    "left_hand",
    "right_hand",
    "left_elbow_ref",
    "right_elbow_ref",
    "head_left",
    "head_right",
    "left_hand_tip",
    "left_hand_side",
    "right_hand_tip",
    "right_hand_side",
)
#: Members of each tracker marker set (the first is the set's primary marker).
MARKER_SET_MEMBERS: dict[str, tuple[str, ...]] = {
    "head": ("head", "head_left", "head_right"),
    "left_hand": ("left_hand", "left_hand_tip", "left_hand_side"),
    "right_hand": ("right_hand", "right_hand_tip", "right_hand_side"),
}

_NAMED_COLOURS_BGR = {
    "red": (40, 40, 190),
    "blue": (170, 90, 40),
    "green": (60, 140, 50),
    "white": (225, 225, 225),
    "black": (35, 35, 35),
    "grey": (120, 120, 120),
    "gray": (120, 120, 120),
    "yellow": (40, 200, 220),
    "orange": (30, 120, 230),
    "purple": (130, 50, 110),
    "teal": (140, 130, 30),
}
_SKIN_TONES_BGR = ((150, 180, 225), (120, 160, 210), (95, 135, 185), (70, 100, 150), (55, 75, 110))
_TROUSERS_BGR = ((80, 55, 35), (60, 60, 60), (110, 110, 120), (40, 35, 30), (90, 110, 140))
_HAIR_BGR = ((30, 40, 60), (20, 25, 30), (50, 90, 140), (40, 60, 90))
#: The paper's belt colour: a dull, dark (antique) gold, RGB (155, 100, 45). Brighter,
#: more saturated golds leave the default skin model's hue band (`mocapkit.cues.skin`)
#: at some light; this one is accepted from 0.5 to 1.12 times its colour (shading 0.72-1
#: times the lighting field's 0.75-1.1), as the paper's belt is by its skin model.
BELT_BGR = (45, 100, 155)
#: Belt band height (mm) and the margin (mm) it stands off the trousers' hull.
BELT_HEIGHT_MM = 70.0
BELT_STANDOFF_MM = 6.0
#: The paper's dress replaces a drawn shirt colour that the skin model accepts in shadow
#: (orange at half light, `mocapkit.cues.skin`) by red, so that the dress is never skin;
#: a substitution rather than a new draw keeps the seeded draws (and the cameras placed
#: after them) those of the everyday clothing.
_DRESS_FOR_SHIRT = {"orange": "red"}


def costume_sleeve(costume: str, sleeve: str | None = None) -> str:
    """The sleeve a costume is drawn with: ``sleeve`` checked against it, or its own.

    Parameters
    ----------
    costume : {"everyday", "paper"}
        `COSTUMES`.
    sleeve : {"short", "long", "none", "elbow"}, optional
        `SLEEVES`; None: the costume's own (everyday: short; paper: elbow, the only one
        it takes).

    Raises
    ------
    ConfigError
        An unknown costume or sleeve, or the paper's costume with other than elbow sleeves.
    """
    if costume not in COSTUMES:
        raise ConfigError(f"costume: expected one of {', '.join(COSTUMES)}, found {costume!r}")
    if sleeve is None:
        return "elbow" if costume == "paper" else "short"
    if sleeve not in SLEEVES:
        raise ConfigError(f"sleeve: expected one of {', '.join(SLEEVES)}, found {sleeve!r}")
    if costume == "paper" and sleeve != "elbow":
        raise ConfigError(
            f"sleeve: the paper's costume covers the upper arms to the elbow; expected "
            f"'elbow' (or none given), found {sleeve!r}"
        )
    return sleeve


def parse_colour(text: str) -> tuple[int, int, int]:
    """A colour name (``red``, ``blue``, ...) or ``#RRGGBB`` to a BGR triple."""
    t = text.strip().lower()
    if t in _NAMED_COLOURS_BGR:
        return _NAMED_COLOURS_BGR[t]
    if len(t) == 7 and t[0] == "#":
        try:
            r, g, b = (int(t[i : i + 2], 16) for i in (1, 3, 5))
        except ValueError:
            pass
        else:
            return (b, g, r)
    raise ConfigError(
        f"colour {text!r}: expected one of {', '.join(sorted(_NAMED_COLOURS_BGR))} or #RRGGBB"
    )


@dataclass(frozen=True)
class Appearance:
    """Colours (BGR, 0-255) and clothing of the rendered subject.

    ``belt``: the colour of a band around the waist (the paper's golden belt), None: no
    belt. `Appearance.random` dresses the subject by `COSTUMES`.
    """

    skin: tuple[int, int, int]
    shirt: tuple[int, int, int]
    trousers: tuple[int, int, int]
    shoes: tuple[int, int, int]
    hair: tuple[int, int, int]
    sleeve: str = "short"
    belt: tuple[int, int, int] | None = None

    @staticmethod
    def random(
        rng: np.random.Generator,
        shirt: str | None = None,
        sleeve: str | None = None,
        costume: str = "everyday",
    ) -> Appearance:
        """A seeded appearance; ``shirt`` (a colour name or #RRGGBB) overrides the draw.

        Parameters
        ----------
        rng : numpy.random.Generator
        shirt : str, optional
            Shirt (the paper's costume: dress) colour; default drawn.
        sleeve : {"short", "long", "none", "elbow"}, optional
            Default: the costume's, ``short`` for ``everyday``, ``elbow`` for ``paper``
            (which takes no other).
        costume : {"everyday", "paper"}
            See `COSTUMES`. Both draw the same numbers from ``rng``.
        """
        sleeve = costume_sleeve(costume, sleeve)
        names = ("red", "blue", "green", "yellow", "orange", "purple", "teal", "white")
        if shirt:
            shirt_bgr = parse_colour(shirt)
        else:
            name = str(rng.choice(names))
            if costume == "paper":
                name = _DRESS_FOR_SHIRT.get(name, name)
            shirt_bgr = _NAMED_COLOURS_BGR[name]
        skin = _SKIN_TONES_BGR[int(rng.integers(len(_SKIN_TONES_BGR)))]
        trousers = _TROUSERS_BGR[int(rng.integers(len(_TROUSERS_BGR)))]
        hair = _HAIR_BGR[int(rng.integers(len(_HAIR_BGR)))]
        if costume == "paper":
            trousers = shirt_bgr  # one dress over the whole body
        return Appearance(
            skin=skin,
            shirt=shirt_bgr,
            trousers=trousers,
            shoes=(30, 30, 35),
            hair=hair,
            sleeve=sleeve,
            belt=BELT_BGR if costume == "paper" else None,
        )


@dataclass(frozen=True)
class Primitive:
    """One body part: a shape over point tracks, with a colour and a depth-sort bias."""

    kind: int
    points: tuple[int, ...]
    radii_mm: tuple[float, ...]
    colour: tuple[int, int, int]
    depth_bias_mm: float = 0.0


@dataclass(frozen=True)
class BodyModel:
    """A fleshed-out body over time.

    Attributes
    ----------
    time_s : (T,) float array
        Sample times (s) of the point tracks.
    points_mm : (T, P, 3) float array
        World positions of every point the primitives reference.
    primitives : tuple of Primitive
    markers_mm : (T, 5, 3) float array
        Clean marker positions in `MARKER_NAMES` order.
    """

    time_s: FloatArray
    points_mm: FloatArray
    primitives: tuple[Primitive, ...]
    markers_mm: FloatArray

    def points_at(self, t_s: FloatArray) -> FloatArray:
        """Point tracks linearly interpolated at times ``t_s`` (N,); returns (N, P, 3)."""
        return interpolate_tracks(self.time_s, self.points_mm, t_s)

    def markers_at(self, t_s: FloatArray) -> FloatArray:
        """Clean markers interpolated at times ``t_s`` (N,); returns (N, 5, 3)."""
        return interpolate_tracks(self.time_s, self.markers_mm, t_s)


def interpolate_tracks(time_s: FloatArray, tracks: FloatArray, t_s: FloatArray) -> FloatArray:
    """Linear interpolation of tracks (T, ...) sampled at ``time_s`` (T,) at times ``t_s`` (N,).

    Times outside the samples are clamped to the first/last sample.
    """
    t = np.clip(np.asarray(t_s, dtype=float), time_s[0], time_s[-1])
    i = np.clip(np.searchsorted(time_s, t, side="right") - 1, 0, len(time_s) - 2)
    span = time_s[i + 1] - time_s[i]
    w = ((t - time_s[i]) / np.where(span > 0, span, 1.0)).reshape(-1, *([1] * (tracks.ndim - 1)))
    return tracks[i] * (1.0 - w) + tracks[i + 1] * w


def joint_roles(skeleton: Skeleton) -> tuple[list[str], list[str]]:
    """Role and side (``left``/``right``/``""``) of the segment each joint owns."""
    owners: dict[int, str] = {}
    # The deepest canonical owner wins (a joint carrying both neck and head is the head).
    order = ["pelvis", "neck", "head"] + [c for c in ROLE_OF_CANONICAL if "_" in c]
    for cname in order:
        if cname in skeleton.canonical:
            owners.setdefault(skeleton.joint_index(skeleton.canonical[cname][0]), cname)
    roles: list[str] = []
    sides: list[str] = []
    for j in range(skeleton.n_joints):
        if j in owners:
            c = owners[j]
            roles.append(ROLE_OF_CANONICAL[c])
            sides.append(c.split("_")[0] if "_" in c else "")
        elif j == 0:
            roles.append("trunk")
            sides.append("")
        else:
            p = int(skeleton.parents[j])
            roles.append(roles[p])
            sides.append(sides[p])
    return roles, sides


def _unit(v: FloatArray) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-9)


def _require_canonical(skeleton: Skeleton) -> None:
    needed = [
        "pelvis",
        "neck",
        "head",
        "left_shoulder",
        "right_shoulder",
        "left_elbow",
        "right_elbow",
        "left_wrist",
        "right_wrist",
        "left_hip",
        "right_hip",
    ]
    missing = [c for c in needed if c not in skeleton.canonical]
    if missing:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: cannot flesh out a body without canonical joints "
            f"{missing}; its canonical map has {sorted(skeleton.canonical)}"
        )


def build_body(
    skeleton: Skeleton,
    time_s: FloatArray,
    q: FloatArray,
    appearance: Appearance,
    shift_mm: FloatArray | None = None,
) -> BodyModel:
    """Flesh out a skeleton moving with ``q`` into rendering primitives and markers.

    Parameters
    ----------
    skeleton : Skeleton
        The motion file's own skeleton with its canonical map.
    time_s : (T,) float array
        Sample times (s).
    q : (T, D) float array
        Joint parameters of ``skeleton``.
    appearance : Appearance
    shift_mm : (3,) float array, optional
        Translation added to every world point (recentring the subject).

    Returns
    -------
    BodyModel
    """
    _require_canonical(skeleton)
    world = forward_kinematics(skeleton, q).copy()  # (T, J, 4, 4)
    if shift_mm is not None:
        world[..., :3, 3] += np.asarray(shift_mm, dtype=float)
    rot = world[..., :3, :3]
    joints = world[..., :3, 3]  # (T, J, 3)
    n_t, n_j = joints.shape[:2]

    def canon(name: str) -> FloatArray:
        jname, point = skeleton.canonical[name]
        j = skeleton.joint_index(jname)
        return joints[:, j] + rot[:, j] @ np.asarray(point, dtype=float)

    rest_world = forward_kinematics(skeleton, skeleton.zero_pose())
    rest = rest_world[..., :3, 3]

    def forearm_rest(side: str) -> FloatArray:
        return _forearm_rest(skeleton, rest_world, side)

    tracks: list[FloatArray] = [joints[:, j] for j in range(n_j)]

    def add(p: FloatArray) -> int:
        tracks.append(p)
        return len(tracks) - 1

    a = appearance
    prims: list[Primitive] = []
    roles, sides = joint_roles(skeleton)
    owner = {c: skeleton.joint_index(skeleton.canonical[c][0]) for c in skeleton.canonical}

    # ------------------------------------------------------------ limbs from the file's bones
    for j in range(1, n_j):
        p = int(skeleton.parents[j])
        length = np.linalg.norm(rest[j] - rest[p])
        if length < 10.0:
            continue
        role = roles[p]
        if role == "trunk":
            kid_sub = set(skeleton.subtree(j).tolist())
            shoulders = [c for c in ("left_shoulder", "right_shoulder") if c in owner]
            if any(owner[c] in kid_sub for c in shoulders) and owner["neck"] not in kid_sub:
                colour = a.skin if a.sleeve == "none" else a.shirt
                prims.append(Primitive(CAPSULE, (p, j), ROLE_RADII_MM["clavicle"], colour))
            continue  # spine and pelvis bones are inside the trunk hulls
        if role == "head":
            continue  # drawn as an ellipsoid below
        if role in ("hand", "foot"):
            # the first bone of a hand or foot is palm or foot, deeper ones fingers or toes
            base = owner[f"{sides[p]}_{'wrist' if role == 'hand' else 'ankle'}"]
            deep = p != base
            key = (
                ("fingers" if deep else "hand") if role == "hand" else ("toes" if deep else "foot")
            )
            colour = a.skin if role == "hand" else a.shoes
            prims.append(Primitive(CAPSULE, (p, j), ROLE_RADII_MM[key], colour))
            continue
        radii = ROLE_RADII_MM[role]
        if role in ("thigh", "shank"):
            prims.append(Primitive(CAPSULE, (p, j), radii, a.trousers))
        elif role == "neck":
            prims.append(Primitive(CAPSULE, (p, j), radii, a.skin))
        elif role == "upper_arm":
            if a.sleeve == "none":
                prims.append(Primitive(CAPSULE, (p, j), radii, a.skin))
            elif a.sleeve in ("long", "elbow"):
                prims.append(Primitive(CAPSULE, (p, j), (radii[0] + 5, radii[1] + 5), a.shirt))
            else:  # short sleeve: the proximal half is covered, the rest is skin
                mid = add(0.5 * (joints[:, p] + joints[:, j]))
                r_mid = 0.5 * (radii[0] + radii[1])
                prims.append(Primitive(CAPSULE, (mid, j), (r_mid, radii[1]), a.skin))
                prims.append(Primitive(CAPSULE, (p, mid), (radii[0] + 6, r_mid + 7), a.shirt, -3.0))
        elif role == "forearm":
            colour = a.shirt if a.sleeve == "long" else a.skin
            extra = 4.0 if a.sleeve == "long" else 0.0
            prims.append(Primitive(CAPSULE, (p, j), (radii[0] + extra, radii[1] + extra), colour))

    # ------------------------------------------------------------ trunk hulls
    lsh, rsh = canon("left_shoulder"), canon("right_shoulder")
    lhip, rhip = canon("left_hip"), canon("right_hip")
    pelvis, neck, head = canon("pelvis"), canon("neck"), canon("head")
    up = _unit(neck - pelvis)
    right_sh = _unit(rsh - lsh)
    right_hip = _unit(rhip - lhip)
    fwd_sh = _unit(np.cross(up, right_sh))
    fwd_hip = _unit(np.cross(up, right_hip))
    sh_w = np.linalg.norm(rsh - lsh, axis=-1, keepdims=True)
    hip_w = np.linalg.norm(rhip - lhip, axis=-1, keepdims=True)
    sh_mid = 0.5 * (lsh + rsh) - 25.0 * up
    hip_mid = 0.5 * (lhip + rhip)
    waist = hip_mid + 0.38 * (sh_mid - hip_mid)
    waist_w = np.maximum(0.5 * sh_w, 0.5 * hip_w + 70.0)
    waist_right = _unit(right_sh + right_hip)
    waist_fwd = _unit(fwd_sh + fwd_hip)
    upper: list[int] = []
    lower: list[int] = []
    for s in (-1.0, 1.0):
        for d in (-1.0, 1.0):
            upper.append(add(sh_mid + s * (0.5 * sh_w - 20.0) * right_sh + d * 85.0 * fwd_sh))
            upper.append(add(waist + s * waist_w * waist_right + d * 100.0 * waist_fwd))
            lower.append(add(waist + 30.0 * up + s * waist_w * waist_right + d * 100.0 * waist_fwd))
            lower.append(
                add(hip_mid - 60.0 * up + s * (0.5 * hip_w + 60.0) * right_hip + d * 95.0 * fwd_hip)
            )
    prims.append(Primitive(HULL, tuple(upper), (), a.shirt, 40.0))
    prims.append(Primitive(HULL, tuple(lower), (), a.trousers, 45.0))
    if a.belt is not None:
        # The belt is worn at the height of the stick's pelvis (the CMU root, about 100 mm
        # above the hip joints: the iliac crests), around the trousers' hull there, whose
        # half-width and depth it takes by linear interpolation between the hull's bottom
        # (hip_mid - 60 up) and top (waist + 30 up) rings, standing off it by
        # BELT_STANDOFF_MM.
        h_belt = np.sum((pelvis - hip_mid) * up, axis=-1, keepdims=True)
        h_top = np.sum((waist + 30.0 * up - hip_mid) * up, axis=-1, keepdims=True)
        f = np.clip((h_belt + 60.0) / np.maximum(h_top + 60.0, 1.0), 0.0, 1.0)
        half_w = (1.0 - f) * (0.5 * hip_w + 60.0) + f * waist_w + BELT_STANDOFF_MM
        half_d = (1.0 - f) * 95.0 + f * 100.0 + BELT_STANDOFF_MM
        right_b = _unit((1.0 - f) * right_hip + f * waist_right)
        fwd_b = _unit(np.cross(up, right_b))
        ring: list[int] = []
        for ang in np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False):
            for dh in (-0.5 * BELT_HEIGHT_MM, 0.5 * BELT_HEIGHT_MM):
                ring.append(
                    add(
                        hip_mid
                        + (h_belt + dh) * up
                        + np.cos(ang) * half_w * right_b
                        + np.sin(ang) * half_d * fwd_b
                    )
                )
        # Drawn over the dress and the thighs' capsules (whose hip ends reach up to the
        # belt) at equal depth; a thigh whose middle comes 10 mm nearer than the waist (a
        # raised knee, a crouch) covers it, as do arms in front.
        prims.append(Primitive(HULL, tuple(ring), (), a.belt, -10.0))

    # ------------------------------------------------------------ head, hair, glasses
    head_j = owner["head"]
    fwd_head = rot[:, head_j] @ np.array([0.0, 1.0, 0.0])  # rest pose faces +Y
    head_up = _unit(head - neck)
    fwd_head = _unit(fwd_head - np.sum(fwd_head * head_up, axis=-1, keepdims=True) * head_up)
    side_head = _unit(np.cross(fwd_head, head_up))
    hc = add(head)
    hx = add(head + side_head)
    hy = add(head + fwd_head)
    hz = add(head + head_up)
    prims.append(Primitive(ELLIPSOID, (hc, hx, hy, hz), HEAD_RADII_MM, a.skin))
    hair_c = head - 28.0 * fwd_head + 22.0 * head_up
    h2 = (add(hair_c), add(hair_c + side_head), add(hair_c + fwd_head), add(hair_c + head_up))
    prims.append(Primitive(ELLIPSOID, h2, (HEAD_RADII_MM[0] + 6, 94.0, 110.0), a.hair))
    for s in (-1.0, 1.0):
        eye = head + 82.0 * fwd_head + 12.0 * head_up + s * 32.0 * side_head
        prims.append(Primitive(SPHERE, (add(eye),), (17.0,), (25, 25, 25), -8.0))
        prims.append(
            Primitive(SPHERE, (add(eye + 4.0 * fwd_head),), (12.0,), (180, 200, 205), -9.0)
        )

    # ------------------------------------------------------------ markers
    markers = np.empty((n_t, len(MARKER_NAMES), 3))
    markers[:, 0] = head + HEAD_MARKER_FORWARD_MM * fwd_head
    mi = MARKER_NAMES.index
    for name, sx in (("head_left", -1.0), ("head_right", 1.0)):
        x, y, z = HEAD_TEMPLE_MM
        markers[:, mi(name)] = head + sx * x * side_head + y * fwd_head + z * head_up
    for k, side in ((1, "left"), (2, "right")):
        wj = owner[f"{side}_wrist"]
        along = forearm_rest(side)  # the hand continues the forearm
        point = np.asarray(skeleton.canonical[f"{side}_wrist"][1], dtype=float)
        local = point + _hand_object_local(along)
        for m, name in enumerate(MARKER_SET_MEMBERS[f"{side}_hand"]):
            markers[:, mi(name)] = joints[:, wj] + rot[:, wj] @ local[m]
        grip = joints[:, wj] + rot[:, wj] @ (point + 45.0 * along)
        g, m = add(grip), add(markers[:, k])
        prims.append(Primitive(CAPSULE, (g, m), (11.0, 11.0), (40, 40, 45), -6.0))
    for k, side in ((3, "left"), (4, "right")):
        ej = owner[f"{side}_elbow"]
        along = forearm_rest(side)
        back = np.array([0.0, -1.0, 0.0]) - (-along[1]) * along
        back = back / max(float(np.linalg.norm(back)), 1e-9)
        point = np.asarray(skeleton.canonical[f"{side}_elbow"][1], dtype=float)
        markers[:, k] = joints[:, ej] + rot[:, ej] @ (point + ELBOW_MARKER_OUT_MM * back)
    for k in range(len(MARKER_NAMES)):
        prims.append(Primitive(SPHERE, (add(markers[:, k]),), (8.0,), (215, 215, 210), -12.0))

    points = np.stack(tracks, axis=1)
    return BodyModel(
        time_s=np.asarray(time_s, dtype=float),
        points_mm=points,
        primitives=tuple(prims),
        markers_mm=markers,
    )


def _forearm_rest(skeleton: Skeleton, rest_world: FloatArray, side: str) -> FloatArray:
    """Unit direction elbow -> wrist at q = 0 (every joint frame is then parallel to the
    world, so it is also the direction in the elbow's and the wrist's own frames)."""
    ends = []
    for c in (f"{side}_elbow", f"{side}_wrist"):
        jname, point = skeleton.canonical[c]
        j = skeleton.joint_index(jname)
        ends.append(rest_world[j, :3, 3] + rest_world[j, :3, :3] @ np.asarray(point, float))
    d = ends[1] - ends[0]
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-6 else np.array([0.0, 0.0, -1.0])


def _hand_object_local(along: FloatArray) -> FloatArray:
    """Offsets (3, 3) from the wrist in the wrist frame (mm) of the hand-held object's
    markers (`MARKER_SET_MEMBERS` order), for a rest forearm direction ``along``: the
    primary beyond the wrist along the forearm line and out towards the rest pose's
    front; the tip further along; the side one off to the object's side."""
    out = np.array([0.0, 1.0, 0.0]) - along[1] * along
    out = out / max(float(np.linalg.norm(out)), 1e-9)
    lateral = np.cross(along, out)
    primary = HAND_MARKER_ALONG_MM * along + HAND_MARKER_OUT_MM * out
    return np.stack(
        [
            primary,
            primary + HAND_OBJECT_TIP_MM * along,
            primary + HAND_OBJECT_SIDE_MM * lateral,
        ]
    )


def declared_marker_offsets(skeleton: Skeleton) -> dict[str, dict[str, object]]:
    """The tracker markers' placement as a lab declares it in ``session.json``.

    Each entry names the canonical joint the marker rides on and its offset (mm) in that
    body part's anatomical frame: x to the subject's right, y forward, z up, with the body
    in the anatomical position (standing, arms hanging, palms forward). The hand offsets
    are turned from the skeleton's own rest pose (a T-pose for CMU skeletons) into that
    position by the smallest rotation taking the rest forearm onto -z.
    """
    rest_world = forward_kinematics(skeleton, skeleton.zero_pose())
    x, y, z = HEAD_TEMPLE_MM
    head = np.array([[0.0, HEAD_MARKER_FORWARD_MM, 0.0], [-x, y, z], [x, y, z]])
    out: dict[str, dict[str, object]] = {"head": _declared_set("head", head)}
    down = np.array([0.0, 0.0, -1.0])
    for side in ("left", "right"):
        along = _forearm_rest(skeleton, rest_world, side)
        axis = np.cross(along, down)
        angle = float(np.arctan2(np.linalg.norm(axis), float(along @ down)))
        n = float(np.linalg.norm(axis))
        anat_from_rest = matrix_from_axis_angle(axis / n, angle) if n > 1e-9 else np.eye(3)
        members = _hand_object_local(along) @ anat_from_rest.T
        out[f"{side}_hand"] = _declared_set(f"{side}_hand", members, f"{side}_wrist")
    return out


def _declared_set(
    name: str, members_mm: FloatArray, segment: str | None = None
) -> dict[str, object]:
    """A ``marker_offsets_mm`` entry: the set centre (mean of the members, as
    `mocapkit.io.marker_sets` evaluates a set) and each member's offset."""

    def r(v: FloatArray) -> list[float]:
        return [round(float(c), 3) for c in v]

    return {
        "segment": segment or name,
        "offset_mm": r(members_mm.mean(axis=0)),
        "members_mm": {m: r(p) for m, p in zip(MARKER_SET_MEMBERS[name], members_mm)},
    }


# ====================================================================== rasterisation

_SHIFT = 2  # fractional bits for sub-pixel OpenCV drawing
_SCALE = float(1 << _SHIFT)


def _shade(colour: tuple[int, int, int], f: float) -> tuple[int, int, int]:
    return (
        int(min(255, colour[0] * f)),
        int(min(255, colour[1] * f)),
        int(min(255, colour[2] * f)),
    )


class CameraRenderer:
    """Draws a `BodyModel` as seen by one camera, including its lens distortion.

    Parameters
    ----------
    camera : Camera
    margin : float
        Extra canvas border (fraction of the image) so that barrel distortion finds
        rendered pixels at the image corners.
    """

    def __init__(self, camera: Camera, margin: float = 0.12) -> None:
        self.camera = camera
        w, h = camera.image_size
        k = np.asarray(camera.K)
        us, vs = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        pix = np.stack([us, vs], axis=-1).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(pix, k, np.asarray(camera.dist)).reshape(h, w, 2)
        fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
        ideal_x = fx * norm[..., 0] + k[0, 1] * norm[..., 1] + cx
        ideal_y = fy * norm[..., 1] + cy
        mx = int(np.ceil(max(0.0, -ideal_x.min(), ideal_x.max() - (w - 1)) + margin * w * 0.1)) + 2
        my = int(np.ceil(max(0.0, -ideal_y.min(), ideal_y.max() - (h - 1)) + margin * h * 0.1)) + 2
        self.canvas_size = (w + 2 * mx, h + 2 * my)
        self.canvas_K = k.copy()
        self.canvas_K[0, 2] += mx
        self.canvas_K[1, 2] += my
        map_x = (ideal_x + mx).astype(np.float32)
        map_y = (ideal_y + my).astype(np.float32)
        self._map1, self._map2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
        self._r = np.asarray(camera.camera_from_world)[:3, :3]
        # the ideal camera of the canvas: no distortion, principal point moved by the margin
        self.canvas_arrays = camera_arrays(self.canvas_K, [], camera.camera_from_world)

    def project_canvas(self, points_in_world: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Ideal canvas pixels (..., 2) and depths (...,) of world points (..., 3).

        Pixels are NaN where a point is not visible (`mocapkit.camera.projection`).
        """
        points_in_camera = self.camera.to_camera(points_in_world)
        px = project(self.canvas_arrays, points_in_camera, in_world=False)
        return px, points_in_camera[..., 2]

    def warp(self, canvas: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """Apply the lens distortion: canvas (ideal camera) to the camera's image."""
        out = cv2.remap(
            canvas, self._map1, self._map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        return np.asarray(out, dtype=np.uint8)

    def draw_body(
        self, canvas: NDArray[np.uint8], primitives: Sequence[Primitive], points_mm: FloatArray
    ) -> None:
        """Draw primitives at one instant into an ideal-camera canvas, far to near.

        Parameters
        ----------
        canvas : (H', W', 3) uint8 array
            Canvas of ``canvas_size``; modified in place.
        primitives : sequence of Primitive
        points_mm : (P, 3) float array
            World positions of the point tracks at this instant.
        """
        px, z = self.project_canvas(points_mm)
        f = float(self.canvas_K[0, 0])
        keys = np.array([float(np.mean(z[list(p.points)])) + p.depth_bias_mm for p in primitives])
        for idx in np.argsort(-keys):
            prim = primitives[int(idx)]
            pts = list(prim.points)
            if np.any(z[pts] <= 50.0) or not np.all(np.isfinite(px[pts])):
                continue  # behind or at the camera
            if prim.kind == CAPSULE:
                self._capsule(
                    canvas,
                    px[pts[0]],
                    px[pts[1]],
                    f * prim.radii_mm[0] / z[pts[0]],
                    f * prim.radii_mm[1] / z[pts[1]],
                    prim.colour,
                )
            elif prim.kind == HULL:
                self._hull(canvas, px[pts], prim.colour)
            elif prim.kind == ELLIPSOID:
                self._ellipsoid(canvas, points_mm[pts], prim.radii_mm, prim.colour)
            else:
                r = f * prim.radii_mm[0] / z[pts[0]]
                self._disc(canvas, px[pts[0]], r, prim.colour)

    @staticmethod
    def _disc(
        canvas: NDArray[np.uint8], c: FloatArray, r: float, colour: tuple[int, int, int]
    ) -> None:
        ci = (round(c[0] * _SCALE), round(c[1] * _SCALE))
        cv2.circle(canvas, ci, max(1, round(r * _SCALE)), colour, -1, cv2.LINE_AA, _SHIFT)

    def _capsule(
        self,
        canvas: NDArray[np.uint8],
        a: FloatArray,
        b: FloatArray,
        ra: float,
        rb: float,
        colour: tuple[int, int, int],
    ) -> None:
        # Two shading layers (darker rim, lighter core shifted towards the light at the
        # upper left) make a flat fill read as a rounded limb.
        for scale, shade, offset in ((1.0, 0.72, 0.0), (0.62, 1.0, 0.22)):
            sa, sb = ra * scale, rb * scale
            shift = np.array([-offset * sa, -offset * sa])
            aa, bb = a + shift, b + shift
            d = bb - aa
            n = np.linalg.norm(d)
            col = _shade(colour, shade)
            if n > 1e-6:
                nrm = np.array([-d[1], d[0]]) / n
                poly = np.array([aa + sa * nrm, bb + sb * nrm, bb - sb * nrm, aa - sa * nrm])
                cv2.fillConvexPoly(
                    canvas, np.round(poly * _SCALE).astype(np.int32), col, cv2.LINE_AA, _SHIFT
                )
            self._disc(canvas, aa, sa, col)
            self._disc(canvas, bb, sb, col)

    @staticmethod
    def _hull(canvas: NDArray[np.uint8], pts: FloatArray, colour: tuple[int, int, int]) -> None:
        hull = cv2.convexHull(np.round(pts * _SCALE).astype(np.int32))
        cv2.fillConvexPoly(canvas, hull, _shade(colour, 0.72), cv2.LINE_AA, _SHIFT)
        centre = pts.mean(axis=0)
        inner = centre + 0.8 * (pts - centre) - np.array([0.03, 0.03]) * (pts.max(0) - pts.min(0))
        hull2 = cv2.convexHull(np.round(inner * _SCALE).astype(np.int32))
        cv2.fillConvexPoly(canvas, hull2, colour, cv2.LINE_AA, _SHIFT)

    def _ellipsoid(
        self,
        canvas: NDArray[np.uint8],
        pts: FloatArray,
        radii: tuple[float, ...],
        colour: tuple[int, int, int],
    ) -> None:
        # Affine approximation of the silhouette: the projection Jacobian J (2x3) at the
        # centre maps the semi-axis matrix A to M = J A; the outline is {M u : |u| = 1},
        # an ellipse with axes from the SVD of M.
        centre = pts[0]
        axes = _unit(pts[1:] - centre) * np.asarray(radii)[:, None]  # (3, 3) rows
        pc = self.camera.to_camera(centre)
        k = self.canvas_K
        x, y, z = pc
        jac = (
            np.array(
                [[k[0, 0] / z, 0.0, -k[0, 0] * x / z**2], [0.0, k[1, 1] / z, -k[1, 1] * y / z**2]]
            )
            @ self._r
        )
        m = jac @ axes.T  # (2, 3)
        u, s, _ = np.linalg.svd(m)
        c2 = np.array([k[0, 0] * x / z + k[0, 2], k[1, 1] * y / z + k[1, 2]])
        angle = float(np.degrees(np.arctan2(u[1, 0], u[0, 0])))
        for scale, shade, offset in ((1.0, 0.75, 0.0), (0.7, 1.0, 0.18)):
            cc = c2 - offset * s[1] * np.array([1.0, 1.0])
            ci = (round(cc[0] * _SCALE), round(cc[1] * _SCALE))
            ax = (
                max(1, round(s[0] * scale * _SCALE)),
                max(1, round(s[1] * scale * _SCALE)),
            )
            cv2.ellipse(
                canvas, ci, ax, angle, 0, 360, _shade(colour, shade), -1, cv2.LINE_AA, _SHIFT
            )
