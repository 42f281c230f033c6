"""The validation misfit of a simulation restarted at the reading after each lost reading.

The validation gap (:func:`~genbacklash_core.diagnose.gap.measure_gap`) is a free run over
the whole record, as the contract asks. On a drivetrain whose load is sensitive to its own
parameters that free run says little about which of two load physics is right: a load that
coasts or rings across the play is chaotic (a load inertia changed by 0.1 % moves the
coasting and compliant physics drivetrains' loads by 0.01-0.05 NRMSE; BENCHMARKS, branch
coast-1), so the free run of any model drifts to that level. The fits do not run free: a
model without a linear block restarts its simulation at the reading after each loss
(:mod:`.fit`), and over those short runs a spring that rings and a load that only coasts
differ by what they are. This misfit measures that prediction on the validation segment,
with the restarts the fit makes, so that the load physics (which all restart alike) can be
compared on held-out data by what they predict rather than by how far they drift.
"""

from __future__ import annotations

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import nrmse

from .gap import Split
from .model import AugmentedModel
from .spec import ModelSpec, anchors_of

__all__ = ["restarted_gap"]


def restarted_gap(
    model: AugmentedModel, u: FloatArray, y: FloatArray, split: Split, breaks: BoolArray
) -> float:
    """NRMSE on the validation segment of ``model`` simulated over the record and restarted
    at the reading after each break (the fits' restarts).

    Parameters
    ----------
    model : AugmentedModel
        A model without a linear block (a cascade's state is not one reading).
    u, y : ndarray
        The whole record's input and output.
    split : Split
        Its estimation and validation segments.
    breaks : ndarray of bool
        The whole record's breaks (True where a sample does not follow the one before).

    Returns
    -------
    float
        The misfit; the free-run gap's when there are no breaks.

    Raises
    ------
    GenBacklashError
        For a model with a linear block.

    Examples
    --------
    >>> import numpy as np
    >>> from genbacklash_core import GeneralBacklash
    >>> from genbacklash_core.diagnose.gap import split_record
    >>> u = np.concatenate([np.linspace(0, 2, 100), np.linspace(2, -2, 100)])
    >>> model = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.3))
    >>> y = model.simulate(u) + 0.5  # an offset the model lacks
    >>> breaks = np.zeros(u.size, dtype=bool)
    >>> breaks[[0, 150]] = True  # a lost reading before sample 150
    >>> split = split_record(u.size, 0.3)
    >>> restarted_gap(model, u, y, split, breaks) < restarted_gap(
    ...     model, u, y, split, np.zeros(u.size, dtype=bool))
    True
    """
    if model.cascade:
        raise GenBacklashError("a model with a linear block cannot restart at a reading")
    spec = ModelSpec.of(model)
    theta = spec.vector(model)
    out = spec.simulate(theta, u, float(y[0]), anchors=anchors_of(breaks), y=y)
    val = split.validation
    return float(nrmse(y[val], out.y[val]))
