"""Refinement of a global model on measured trajectories (multiple shooting, Levenberg-Marquardt)."""

from ._refine import (
    RefineSettings as RefineSettings,
    ShootingProblem as ShootingProblem,
    free_mask as free_mask,
    refine as refine,
    shooting_problem as shooting_problem,
)
from ._shooting import OutputError as OutputError, output_error as output_error
