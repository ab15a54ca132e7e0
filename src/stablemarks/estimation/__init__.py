"""The joint EKF over the robot pose and the landmarks, and data association (paper Sec 5).

:mod:`.ekf` holds the filter (prediction Eq 19, update Eq 20 in Joseph form, gating, joint
compatibility, information-based choice of the landmarks to update with); :mod:`.association` decides
which of a frame's segment pairs is which landmark (pattern along walls, image-space gating, heights,
polarity); :mod:`.relocalize` finds the pose from the landmarks on a frame's lines when the prediction has
lost it (a slip, a kidnap).
"""

from .association import (
    associate_frame,
    height_cost,
    is_duplicate,
    match_along_wall,
    merged_with_edges,
    polarity_cost,
    wall_polarity,
)
from .ekf import (
    BLAS_PIN_MIN_DIM,
    EDGES,
    KINDS,
    EKFConfig,
    JointEKF,
    LandmarkEstimate,
    NewLandmark,
    ObservationPrediction,
    UpdateResult,
    _add_sym_rank,
    motion,
)

__all__ = [
    "BLAS_PIN_MIN_DIM", "EDGES", "KINDS", "EKFConfig", "JointEKF", "LandmarkEstimate", "NewLandmark",
    "ObservationPrediction", "UpdateResult", "_add_sym_rank", "associate_frame", "height_cost", "is_duplicate",
    "match_along_wall", "merged_with_edges", "motion", "polarity_cost", "wall_polarity",
]
