"""mocapkit: human motion capture from markers plus one camera, one video, or a stereo pair.

Units are millimetres and seconds throughout; angles are radians inside the library.
The world frame is right-handed and Z-up (as C3D and most marker labs); a subject at
rest faces +Y with their right side towards +X.
"""

from mocapkit.errors import (
    CalibrationError,
    ConfigError,
    FormatError,
    MocapError,
    SessionError,
    ShapeError,
    UnknownNameError,
)

__version__ = "0.1.0"

__all__ = [
    "CalibrationError",
    "ConfigError",
    "FormatError",
    "MocapError",
    "SessionError",
    "ShapeError",
    "UnknownNameError",
    "__version__",
]
