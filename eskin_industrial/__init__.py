"""eskin-industrial: electronic-skin tactile arrays on industrial grippers.

Sources (``bus``) turn a transport into frames, the detector (``detect``) turns frames
into grasp states, and the register image maps those onto a PLC.
"""

from .calibration import Calibrator
from .errors import DecodeError, EskinError, InputFormatError, ProfileError
from .frames import Frame, FrameFlag
from .profile import Profile, load_profile, parse_profile

__version__ = "0.1.0"

__all__ = [
    "Calibrator", "DecodeError", "EskinError", "Frame", "FrameFlag", "InputFormatError",
    "Profile", "ProfileError", "__version__", "load_profile", "parse_profile",
]
