"""2-D joints from skin blobs, as Mamania et al. (2004, §3.2-3.3) track a dancer.

Per frame: the skin mask (`mocapkit.cues.skin.skin_mask`), blobs and their ellipses
(`mocapkit.cues.blobs.mask_blobs`), blobs labelled head, left and right forearm/hand and
waist (the paper's golden belt, which its skin model also accepts), joints read off the
ellipses, then the fixed-lag smoother of the tracker (errata M6).

Labels. First frame (the subject faces the camera, as the paper's initial pose is known):
of the four largest blobs, the three that reach highest (the top ends of their major
axes) are the head and the forearms, and the head is the middle one of them from left to
right if its top lies above the other two's centroids (else, or with fewer than three,
the one reaching highest: the top of the head is the subject's highest skin unless a
hand is raised). Neither a raised forearm whose centroid
lies above the head's (or above that of a head merged with the other arm, as in the
first frame of one dance clip) nor a hand raised above the head is taken for it, as the
topmost centroid or the highest top alone would; the waist is a blob below the head
whose major axis lies within 30 deg of the horizontal; the other two are the forearms, the
subject's left one on the image's right. Later frames: each label takes the blob nearest
its previous centre (minimum total distance, `scipy.optimize.linear_sum_assignment`)
within ``max_jump_px``. Two labels whose blobs merged (a hand in front of the face) both
point at one blob: the label that matched it keeps it, the other keeps its previous
ellipse moved with the merged blob's centroid (the paper separates merged blobs by
following the merging ellipses through the previous frame). A label with no blob near
it is unseen (NaN) for that frame.

``belt`` (the subject wears the paper's belt, as the synthetic sessions in the paper's
costume do, `mocapkit.synth.render.COSTUMES`): the first frame's waist is the lowest flat
blob below the head however many blobs there are (without ``belt`` it needs all four, so
that a flat forearm in clothing without a belt is not taken for it), and a waist label
lost in a later frame is given again to such an unlabelled blob among the four largest.
A forearm hanging at the hip merges with the belt into one flat blob in the first frames
of two clips (and a head merged with a forearm in a third leaves three blobs),
so the four-blob rule missed the waist in three of the five clips.
``reacquire``: a hand label lost (or never found) is given to an unlabelled blob of the
four largest on its side of the head (the subject's left on the image's right), so a
forearm that leaves the belt it hung against is labelled again.

Joints from the ellipses (§3.3): head = the head ellipse's centre; neck = the lower end of
its major axis; elbow and wrist = the ends of a forearm ellipse's major axis, the one
nearer the neck being the elbow (the paper's costume leaves the forearm bare); pelvis = the
waist ellipse's centre; shoulders by the paper's heuristic: "exactly above the waist
region endpoints and in horizontal line with the lower end of the neck". Without a waist
blob (no belt), pelvis and shoulders are unseen, and the 3-D tracker has no trunk.

``trunk_from_head`` (off by default; not in the paper) stands in for the belt on footage
without one: with no waist blob, an upright trunk is drawn from the head ellipse by the
anthropometric ratios of `mocapkit.tracking.mono.lengths.ANTHROPOMETRIC_RATIOS` (the
head link, neck to head centre, is the ellipse's semi-major axis a): the pelvis lies
``a * trunk / head`` straight below the neck in the image and the shoulders
``a * clavicle / head`` either side of it. The trunk then never leans or turns, which is
wrong whenever the subject bends; it lets the 3-D step run on real video.

``bare_from`` (off by default; the paper takes the axis' ends) reads the elbow and wrist
off an arm blob by the costume instead: the skin runs from ``bare_from`` (the elbow, the
middle of the upper arm under short sleeves, or the shoulder) to the fingertips, so the
blob is that part of the upper arm, the forearm and the hand in line. Its extent along the
major axis is taken as a thin rod's, sqrt(3)/2 of the moment ellipse's semi-major axis
either side of the centre (a uniform rod of length l has the second moment l^2/12), and
the elbow and wrist lie on it at the fractions of the visible lengths (`ARM_RATIOS`;
proximal end = the end nearer the neck, as above). A bent arm is read as if straight.

Foreground (optional, `SkinTracker.update`): a mask of moving pixels
(`mocapkit.cues.foreground`) that the skin mask is intersected with, for scenes whose
background holds skin-coloured things.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from mocapkit.cues.blobs import Blob, mask_blobs
from mocapkit.cues.skin import ColourModel, skin_mask
from mocapkit.errors import ConfigError
from mocapkit.tracking.mono.lengths import ANTHROPOMETRIC_RATIOS

FloatArray = NDArray[np.float64]

#: Half-length of a uniform thin rod over its moment ellipse's semi-major axis, sqrt(3)/2.
ROD_EXTENT = float(np.sqrt(3.0) / 2.0)
#: Segment lengths over stature for the arm blob: upper arm and forearm as the tracker's
#: ratios (`ANTHROPOMETRIC_RATIOS`), the hand (wrist to the middle fingertip) 0.108 as in
#: Drillis & Contini's segment proportions (Winter, Biomechanics and Motor Control of
#: Human Movement, 4th ed., fig. 4.1).
ARM_RATIOS: dict[str, float] = {
    "upper_arm": ANTHROPOMETRIC_RATIOS["left_upper_arm"],
    "forearm": ANTHROPOMETRIC_RATIOS["left_forearm"],
    "hand": 0.108,
}
#: Share of the upper arm that is bare, per ``bare_from``.
BARE_UPPER_ARM: dict[str, float] = {"elbow": 0.0, "mid_upper_arm": 0.5, "shoulder": 1.0}


def arm_fractions(bare_from: str) -> tuple[float, float]:
    """Elbow and wrist as fractions (0-1) of an arm blob's length from its proximal end.

    Parameters
    ----------
    bare_from : {"elbow", "mid_upper_arm", "shoulder"}
        Where the skin starts on the arm; it runs to the fingertips.
    """
    if bare_from not in BARE_UPPER_ARM:
        raise ConfigError(
            f"arm_fractions: expected bare_from in {sorted(BARE_UPPER_ARM)}, found {bare_from!r}"
        )
    u = BARE_UPPER_ARM[bare_from] * ARM_RATIOS["upper_arm"]
    f, h = ARM_RATIOS["forearm"], ARM_RATIOS["hand"]
    return u / (u + f + h), (u + f) / (u + f + h)


LABELS: tuple[str, ...] = ("head", "left_hand", "right_hand", "waist")
#: Joints this tracker reads off the blobs, in `stick_model` order.
SKIN_JOINTS: tuple[str, ...] = (
    "neck", "pelvis", "left_shoulder", "right_shoulder", "head", "left_elbow", "left_wrist",
    "right_elbow", "right_wrist",
)  # fmt: skip


@dataclass
class SkinFrame:
    """Labelled blobs of one frame and the joints read off them.

    Attributes
    ----------
    blobs : dict of str to Blob
        Per label, its ellipse this frame (absent: unseen).
    merged : set of str
        Labels whose ellipse was carried through a merge.
    joints_px : (9, 2) float
        `SKIN_JOINTS` in pixels, NaN where unseen.
    """

    blobs: dict[str, Blob]
    merged: set[str] = field(default_factory=set)
    joints_px: FloatArray = field(default_factory=lambda: np.full((len(SKIN_JOINTS), 2), np.nan))


def _moved(blob: Blob, shift: FloatArray) -> Blob:
    return Blob(
        blob.centre + shift, blob.area, blob.major, blob.minor, blob.direction, blob.ends + shift
    )


class SkinTracker:
    """Labels skin blobs frame to frame and reads the stick's joints off them.

    Parameters
    ----------
    model : ColourModel, optional
        Skin colour model (default `mocapkit.cues.skin.DEFAULT_SKIN`).
    min_area_px : int
        Smallest blob.
    close_px : int
        Closing radius that reunites broken blobs.
    max_jump_px : float
        Largest centre motion between frames of one label.
    trunk_from_head : bool
        Without a waist blob, draw an upright trunk from the head ellipse (see the module
        docstring).
    belt : bool
        The subject wears the paper's belt (see the module docstring).
    reacquire : bool
        Give lost hand labels to unlabelled blobs on their side (module docstring).
    bare_from : {None, "elbow", "mid_upper_arm", "shoulder"}
        Where the arms' skin starts; None (default): the paper's rule, the ellipse's ends
        are the elbow and wrist. Else the joints at the costume's fractions
        (`arm_fractions`; the synthetic renderer's default short sleeves:
        ``"mid_upper_arm"``).
    """

    def __init__(
        self,
        model: ColourModel | None = None,
        min_area_px: int = 30,
        close_px: int = 2,
        max_jump_px: float = 60.0,
        trunk_from_head: bool = False,
        bare_from: str | None = None,
        belt: bool = False,
        reacquire: bool = False,
    ) -> None:
        if min_area_px < 1 or close_px < 0 or max_jump_px <= 0:
            raise ConfigError(
                f"SkinTracker: expected min_area_px >= 1, close_px >= 0, max_jump_px > 0; "
                f"found {min_area_px}, {close_px}, {max_jump_px}"
            )
        self.model = model
        self.min_area_px = min_area_px
        self.close_px = close_px
        self.max_jump_px = max_jump_px
        self.trunk_from_head = trunk_from_head
        self.arm_fractions = None if bare_from is None else arm_fractions(bare_from)
        self.belt = belt
        self.reacquire = reacquire
        self.previous: SkinFrame | None = None

    def update(self, image_bgr: ArrayLike, foreground: ArrayLike | None = None) -> SkinFrame:
        """Track one frame (H, W, 3) BGR; ``foreground`` (H, W), non-zero on the pixels
        skin may lie on (default: everywhere)."""
        mask = skin_mask(image_bgr, self.model)
        if foreground is not None:
            fg = np.asarray(foreground)
            if fg.shape != mask.shape:
                raise ConfigError(
                    f"SkinTracker.update: expected a foreground mask of shape {mask.shape}, "
                    f"found {fg.shape}"
                )
            mask = np.where(fg != 0, mask, 0).astype(np.uint8)
        return self.update_blobs(mask_blobs(mask, self.min_area_px, self.close_px))

    def update_blobs(self, blobs: list[Blob]) -> SkinFrame:
        """Track one frame from its blobs (largest first)."""
        frame = self._first(blobs) if self.previous is None else self._follow(blobs)
        frame.joints_px = joints_from_blobs(frame.blobs, self.trunk_from_head, self.arm_fractions)
        if frame.blobs:
            self.previous = frame
        return frame

    def _first(self, blobs: list[Blob]) -> SkinFrame:
        cands = blobs[:4]
        if not cands:
            return SkinFrame({})
        head = _first_head(cands)
        rest = [b for b in cands if b is not head]
        labelled: dict[str, Blob] = {"head": head}
        w = _waist_below(head, rest)
        if w is not None and (len(rest) >= 3 or self.belt):
            labelled["waist"] = w
            rest = [b for b in rest if b is not w]
        hands = sorted(rest[:2], key=lambda b: b.centre[0])
        if len(hands) == 2:
            labelled["right_hand"], labelled["left_hand"] = hands
        elif len(hands) == 1:
            side = "left_hand" if hands[0].centre[0] > head.centre[0] else "right_hand"
            labelled[side] = hands[0]
        return SkinFrame(labelled)

    def _follow(self, blobs: list[Blob]) -> SkinFrame:
        prev = self.previous
        assert prev is not None
        names = [n for n in LABELS if n in prev.blobs]
        labelled: dict[str, Blob] = {}
        merged: set[str] = set()
        if blobs and names:
            cost = np.array(
                [[np.linalg.norm(b.centre - prev.blobs[n].centre) for b in blobs] for n in names]
            )
            rows, cols = linear_sum_assignment(cost)
            taken = {}
            for r, c in zip(rows, cols):
                if cost[r, c] <= self.max_jump_px:
                    labelled[names[r]] = blobs[c]
                    taken[c] = names[r]
            for r, n in enumerate(names):
                if n in labelled:
                    continue
                # merged: the nearest blob already belongs to another label and covers
                # this label's previous centre
                c = int(np.argmin(cost[r]))
                b = blobs[c]
                if c in taken and cost[r, c] <= b.major + self.max_jump_px:
                    owner = taken[c]
                    shift = b.centre - prev.blobs[owner].centre
                    labelled[n] = _moved(prev.blobs[n], shift)
                    merged.add(n)
        if (self.reacquire or self.belt) and blobs:
            self._reacquire(blobs[:4], labelled)
        return SkinFrame(labelled, merged)

    def _reacquire(self, cands: list[Blob], labelled: dict[str, Blob]) -> None:
        """Give the waist (with ``belt``) and hands (with ``reacquire``) missing this frame
        to unlabelled blobs of ``cands`` (in place); see the module docstring."""
        used = {id(b) for b in labelled.values()}
        free = [b for b in cands if id(b) not in used]
        head = labelled.get("head")
        if head is None or not free:
            return
        if self.belt and "waist" not in labelled:
            w = _waist_below(head, free)
            if w is not None:
                labelled["waist"] = w
                free = [b for b in free if b is not w]
        for side, sign in (("left_hand", 1.0), ("right_hand", -1.0)):
            if side in labelled or not self.reacquire:
                continue
            mine = [b for b in free if sign * (b.centre[0] - head.centre[0]) > 0]
            if mine:
                labelled[side] = mine[0]
                free = [b for b in free if b is not mine[0]]


def _waist_below(head: Blob, blobs: list[Blob]) -> Blob | None:
    """The lowest of ``blobs`` that could be the waist: below the head by more than its
    semi-major axis and lying within 30 deg of the horizontal; None if there is none."""
    flat = [
        b for b in blobs
        if b.centre[1] > head.centre[1] + head.major and abs(b.direction[1]) < 0.5
    ]  # fmt: skip
    return max(flat, key=lambda b: b.centre[1]) if flat else None


def _first_head(cands: list[Blob]) -> Blob:
    """The head among the first frame's largest blobs; see the module docstring."""
    top = sorted(cands, key=lambda b: b.ends[0, 1])[:3]
    if len(top) < 3:
        return top[0]
    mid = sorted(top, key=lambda b: b.centre[0])[1]
    if all(mid.ends[0, 1] < b.centre[1] for b in top if b is not mid):
        return mid
    return top[0]


def joints_from_blobs(
    blobs: dict[str, Blob],
    trunk_from_head: bool = False,
    fractions: tuple[float, float] | None = None,
) -> FloatArray:
    """`SKIN_JOINTS` (9, 2) px read off labelled ellipses; see the module docstring.

    ``trunk_from_head``: without a waist blob, the upright trunk drawn from the head.
    ``fractions``: elbow and wrist along an arm blob's rod extent from its proximal end
    (`arm_fractions`); None: the ellipse's ends.
    """
    out = np.full((len(SKIN_JOINTS), 2), np.nan)
    col = {n: i for i, n in enumerate(SKIN_JOINTS)}
    head = blobs.get("head")
    if head is not None:
        out[col["head"]] = head.centre
        out[col["neck"]] = head.ends[1]  # the lower end
    neck = out[col["neck"]]
    for side in ("left", "right"):
        b = blobs.get(f"{side}_hand")
        if b is None:
            continue
        ref = neck if np.isfinite(neck).all() else b.centre
        d = np.linalg.norm(b.ends - ref, axis=1)
        near, far = (0, 1) if d[0] <= d[1] else (1, 0)
        if fractions is None:
            out[col[f"{side}_elbow"]] = b.ends[near]
            out[col[f"{side}_wrist"]] = b.ends[far]
            continue
        p0 = b.centre + ROD_EXTENT * (b.ends[near] - b.centre)
        p1 = b.centre + ROD_EXTENT * (b.ends[far] - b.centre)
        out[col[f"{side}_elbow"]] = p0 + fractions[0] * (p1 - p0)
        out[col[f"{side}_wrist"]] = p0 + fractions[1] * (p1 - p0)
    waist = blobs.get("waist")
    if waist is not None:
        out[col["pelvis"]] = waist.centre
        if np.isfinite(neck).all():
            xs = sorted(waist.ends[:, 0])
            out[col["right_shoulder"]] = (xs[0], neck[1])  # the subject's right: image left
            out[col["left_shoulder"]] = (xs[1], neck[1])
    elif trunk_from_head and head is not None:
        r = ANTHROPOMETRIC_RATIOS
        a = head.major
        out[col["pelvis"]] = neck + np.array([0.0, a * r["trunk"] / r["head"]])
        half = a * r["left_clavicle"] / r["head"]
        out[col["right_shoulder"]] = neck - np.array([half, 0.0])
        out[col["left_shoulder"]] = neck + np.array([half, 0.0])
    return out
