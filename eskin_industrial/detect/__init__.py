"""The numeric core: frames in, indicator updates and grasp states out. No I/O here."""

from .methods import METHODS, Method, get_method
from .paper import PaperDetector, paper_batch
from .settings import DetectorSettings, Geometry
from .state import LABELS, GraspState, StateMachine
from .updates import COLUMNS, Update, UpdateTable

__all__ = [
    "COLUMNS", "LABELS", "METHODS", "DetectorSettings", "Geometry", "GraspState", "Method",
    "PaperDetector", "StateMachine", "Update", "UpdateTable", "get_method", "paper_batch",
]
