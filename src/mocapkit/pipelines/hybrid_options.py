"""What ``mocapkit track hybrid`` is asked for, with the rules of its options stated once.

A run tracks either a session folder (video refinement options) or a raw marker file
(IK only: marker sets, subject and lab frame options); `HybridRunOptions` refuses the
options of the other input and the pairs that contradict each other, naming them, when
it is made.
"""

from __future__ import annotations

from dataclasses import dataclass

from mocapkit.errors import SessionError


@dataclass(frozen=True)
class HybridRunOptions:
    """The input of a hybrid run and the options it was given (None/False: not given).

    Attributes
    ----------
    session, markers : str or None
        A session folder, or a raw marker file (.c3d, .trc, .csv): exactly one.
    no_video, paper, positions_only, oriented_sets, max_elbow_speed_mm_per_s
        Options of a session run (``--no-video`` ... ``--max-elbow-speed``).
    marker_set, height_mm, free_feet, up, floor_mm, world_frame, static,
    no_static_calibration, calibration
        Options of a marker-file run (``--marker-set`` ... ``--calibration``).
    """

    session: str | None = None
    markers: str | None = None
    no_video: bool = False
    paper: bool = False
    positions_only: bool = False
    oriented_sets: str | None = None
    max_elbow_speed_mm_per_s: float | None = None
    marker_set: tuple[str, ...] = ()
    height_mm: float | None = None
    free_feet: bool = False
    up: str | None = None
    floor_mm: float | None = None
    world_frame: bool = False
    static: str | None = None
    no_static_calibration: bool = False
    calibration: str | None = None

    def __post_init__(self) -> None:
        if self.markers:
            if self.session:
                raise SessionError(
                    "track hybrid: give either a SESSION folder or --markers FILE, not both"
                )
            _refuse(
                self._given_session_options(),
                "apply to a SESSION; --markers runs IK only",
            )
            if self.no_static_calibration and self.calibration not in (None, "none"):
                raise SessionError(
                    f"track hybrid: --no-static-calibration means --calibration none; found "
                    f"--calibration {self.calibration} with it"
                )
            return
        if not self.session:
            raise SessionError(
                "track hybrid: expected a SESSION folder or --markers FILE, found neither"
            )
        _refuse(
            self._given_marker_file_options(),
            "apply to --markers; a SESSION takes its marker sets and subject from session.json",
        )
        if self.max_elbow_speed_mm_per_s is not None and (self.paper or self.no_video):
            raise SessionError(
                "track hybrid: --max-elbow-speed tunes the video refinement's elbow-jump "
                "penalty, which --paper and --no-video do not run"
            )
        if self.positions_only and self.oriented_sets is not None:
            raise SessionError(
                "track hybrid: give either --positions-only or --oriented-sets, not both"
            )

    def _given_session_options(self) -> list[str]:
        return [
            o
            for o, on in (
                ("--no-video", self.no_video),
                ("--paper", self.paper),
                ("--positions-only", self.positions_only),
                ("--oriented-sets", self.oriented_sets is not None),
                ("--max-elbow-speed", self.max_elbow_speed_mm_per_s is not None),
            )
            if on
        ]

    def _given_marker_file_options(self) -> list[str]:
        return [
            o
            for o, on in (
                ("--marker-set", bool(self.marker_set)),
                ("--height-mm", self.height_mm is not None),
                ("--free-feet", self.free_feet),
                ("--up", self.up is not None),
                ("--floor-mm", self.floor_mm is not None),
                ("--world-frame", self.world_frame),
                ("--static", self.static is not None),
                ("--no-static-calibration", self.no_static_calibration),
                ("--calibration", self.calibration is not None),
            )
            if on
        ]

    @property
    def member_calibration(self) -> str:
        """The member calibration of a marker-file run (``--calibration``; default auto)."""
        return "none" if self.no_static_calibration else (self.calibration or "auto")

    @property
    def oriented(self) -> tuple[str, ...] | None:
        """The marker sets whose orientation a session run uses (None: all)."""
        from mocapkit.pipelines.hybrid import parse_oriented_sets

        if self.positions_only:
            return ()
        return None if self.oriented_sets is None else parse_oriented_sets(self.oriented_sets)


def _refuse(options: list[str], why: str) -> None:
    if options:
        raise SessionError(f"track hybrid: {', '.join(options)} {why}")


__all__ = ["HybridRunOptions"]
