"""genbacklash_core: general backlash models, simulation and identification (numpy + scipy only).

This package never imports ROS, bag or DDS libraries; a controls engineer can import it into
their own loop. See ``genbacklash_ros`` for IO, the node and the command line.
"""

from __future__ import annotations

import sys

if sys.version_info < (3, 10):  # noqa: UP036 - not declared in the metadata (colcon)
    raise ImportError(f"genbacklash needs Python 3.10 or newer; this is {sys.version.split()[0]}")

from .backlash import GeneralBacklash
from .cascade import Cascade
from .data import check_excitation, count_reversals, prepare_series
from .errors import GenBacklashError, NonFiniteInputError, NotEnoughExcitationError
from .estimate import Estimate, EstimatorState, OnlineIdentifier, track
from .examples import ExampleData, PaperExample, paper_example
from .excite import (
    CommissioningCheck,
    MotionLimits,
    Trajectory,
    check_commissioning,
    commissioning_trajectory,
)
from .guard import CompensationGuard, GuardSettings, GuardVerdict
from .identify import (
    Fit,
    IdentificationResult,
    IterationHistory,
    identify_backlash,
    identify_cascade,
    nrmse,
)
from .inverse import (
    CompensatorOptions,
    CompensatorState,
    InverseBacklash,
    branch_inverse,
    compensate,
    compensate_step,
    hold_interval,
)
from .linear import LinearBlock, simulate_linear
from .online.recursive import RecursiveIdentifier, RecursiveSettings
from .online.windowed import WindowedIdentifier, WindowedSettings
from .play import play_operator, play_operator_loop
from .refine import RefinementResult, refine_output_error
from .simulate import (
    CascadeOutput,
    simulate_backlash,
    simulate_backlash_loop,
    simulate_cascade,
    simulate_cascade_loop,
)
from .structure import Structure

__version__ = "0.1.0"

__all__ = [
    "Cascade",
    "CascadeOutput",
    "CommissioningCheck",
    "CompensationGuard",
    "CompensatorOptions",
    "CompensatorState",
    "Estimate",
    "EstimatorState",
    "ExampleData",
    "Fit",
    "GenBacklashError",
    "GeneralBacklash",
    "GuardSettings",
    "GuardVerdict",
    "IdentificationResult",
    "InverseBacklash",
    "IterationHistory",
    "LinearBlock",
    "MotionLimits",
    "NonFiniteInputError",
    "NotEnoughExcitationError",
    "OnlineIdentifier",
    "PaperExample",
    "RecursiveIdentifier",
    "RecursiveSettings",
    "RefinementResult",
    "Structure",
    "Trajectory",
    "WindowedIdentifier",
    "WindowedSettings",
    "__version__",
    "branch_inverse",
    "check_commissioning",
    "check_excitation",
    "commissioning_trajectory",
    "compensate",
    "compensate_step",
    "count_reversals",
    "hold_interval",
    "identify_backlash",
    "identify_cascade",
    "nrmse",
    "paper_example",
    "play_operator",
    "play_operator_loop",
    "prepare_series",
    "refine_output_error",
    "simulate_backlash",
    "simulate_backlash_loop",
    "simulate_cascade",
    "simulate_cascade_loop",
    "simulate_linear",
    "track",
]
