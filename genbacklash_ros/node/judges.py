"""The two judges of the model in use, and what they set on the compensator.

Whether compensating with the identified model helps is judged twice:

* the compensation guard (:class:`~genbacklash_core.guard.CompensationGuard`) replays the
  screened samples fed to the identifier with and without the model's inverse;
* the measured tracking (:class:`~genbacklash_ros.node.tracking_stage.TrackingStage` and its
  :class:`~genbacklash_core.measured.TrackingJudge`) compares the readings with the desired
  position, with and without compensation in force.

:class:`CompensationJudges` holds both for one start of the pipeline and turns their verdicts
into the compensator's ``trust`` (the guard's) and ``share`` (the judge's;
:class:`~genbacklash_ros.node.compensate.CompensateStage`): a new model is judged at once on
the samples the guard remembers and the judge learns its play; a model the guard lets back
after an "off" is measured afresh, with a trial; a checkpoint's model waits for the guard's
first verdict on this machine's samples when the checkpoint carries its record's tracking
without compensation, and stays off when it carries a verdict of harm.
"""

from __future__ import annotations

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash
from genbacklash_core.guard import CompensationGuard
from genbacklash_ros.node.checkpoint import WarmStart
from genbacklash_ros.node.compensate import CompensateStage
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.tracking_stage import TrackingStage

__all__ = ["CompensationJudges", "play_of"]


def play_of(model: object) -> float | None:
    """``c_L + c_R`` of a model's backlash (None without a model).

    >>> from genbacklash_core import GeneralBacklash
    >>> play_of(GeneralBacklash([1.0], 0.02, [1.0], 0.03))
    0.05
    >>> play_of(None) is None
    True
    """
    if isinstance(model, Cascade):
        model = model.backlash
    if isinstance(model, GeneralBacklash):
        return float(model.c_left + model.c_right)
    return None


class CompensationJudges:
    """The guard and the measured tracking over the model in use, for one start.

    Parameters
    ----------
    params : NodeParameters
        The guard's and the judge's settings.
    comp : CompensateStage
        The compensator whose ``trust`` and ``share`` the verdicts set.
    start : WarmStart
        What the start took from its checkpoint: the model, its record's tracking without
        compensation (``baseline``) and a verdict of harm.

    Attributes
    ----------
    guard : CompensationGuard
    tracking : TrackingStage
    await_guard : bool
        The checkpoint's model waits for the guard's first verdict on live samples.
    """

    __slots__ = ("_comp", "_guard_off", "await_guard", "guard", "tracking")

    def __init__(self, params: NodeParameters, comp: CompensateStage, start: WarmStart) -> None:
        self._comp = comp
        self.guard = CompensationGuard(params.guard_settings())
        self.tracking = TrackingStage(params.judge_settings())
        # a checkpoint that holds its record's tracking without compensation: the judge
        # starts from it, and the model waits for the guard's first verdict on live samples
        # (min_samples of them): a load that coasts into the play or a coupling that rings
        # is perturbed for the rest of a record by a trial of a second at a tenth of its
        # weight (BENCHMARKS.md, issue 23, base-1), and the guard tells them apart first
        self.await_guard = start.prior is not None and start.baseline is not None
        self._guard_off = False  # the guard's last verdict was "off"
        judge = self.tracking.judge
        if self.await_guard:
            assert start.baseline is not None
            judge.start_from(start.baseline)
        if start.prior is not None:
            play = play_of(start.prior.model)
            if play is not None:  # the judge knows the play of the model it judges
                judge.new_model(play)
            if start.harm is not None:
                # the model the last node measured tracking worse than without stays off
                # until a new model or the retry, as in a running node (BENCHMARKS.md,
                # issue 23: a restart that tried it again tracked 2.4 % worse)
                judge.hold(start.harm)
        self.apply()  # a checkpoint's model is judged from its first command

    def configure(self, params: NodeParameters) -> None:
        """New settings for both (the evidence kept)."""
        self.guard.configure(params.guard_settings())
        self.tracking.judge.configure(params.judge_settings())
        self.apply()

    def judge_samples(
        self,
        us: np.ndarray,
        ys: np.ndarray,
        restarts: np.ndarray,
        model: GeneralBacklash | Cascade | None,
    ) -> None:
        """Samples screened for the identifier: does compensating with ``model`` help on
        them (the guard, which fades it if not; ``restarts``: where the drivetrain's path
        since the sample before is not known, the screen's
        :attr:`~genbacklash_ros.node.screen.Screened.restarts`), and the tracking measured on
        every reading since (the judge)."""
        self.guard.update(us, ys, restarts, model)
        self.tracking.flush()
        self.apply()

    def adopt(self, model: GeneralBacklash | Cascade | None) -> None:
        """A new model in use: judged at once on the samples the guard remembers."""
        self.guard.adopt(model)
        play = play_of(model)
        if play is not None:
            self.tracking.judge.new_model(play)
        self.apply()

    def apply(self) -> None:
        """The compensator's trust (the guard's judgement of the model) and share (the
        judge's of the tracking measured)."""
        guard = self.guard.verdict
        self._comp.trust = guard.trust
        off = guard.state == "off"
        if self._guard_off and not off:
            # back after the guard held it off: measured afresh, with a trial (the judge)
            self.tracking.judge.resume()
        self._guard_off = off
        if self.await_guard and (
            guard.samples >= self.guard.settings.min_samples or not self.guard.settings.enabled
        ):
            self.await_guard = False
        self._comp.share = 0.0 if self.await_guard else self.tracking.verdict.trust
