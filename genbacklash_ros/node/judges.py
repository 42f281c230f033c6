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

With the servo modelled (``servo_model`` auto or fixed) the guard judges the model twice, and
the stricter verdict counts: on the rows' input, the modelled servo output (what the model
was fitted on), and on the **commands** themselves (a second
:class:`~genbacklash_core.guard.CompensationGuard`: the model's backlash run on the commands,
against the load left where the command is). The compensator inverts the play only, not the
servo (no lead), and the tracking error without compensation is the load against the
command, so what compensating leaves is the play operator's error on the commands; a servo
model fitted with the play can take up a load's own dynamics (a coupling's spring, a load
coasting on), and the model then describes the servo-output samples while the play alone
does not describe the load against the command. Measured in BENCHMARKS.md (issue 23,
"a second yardstick": the compliant, coasting and gravity drivetrains whose trials cost 2-9 %
of a record with ``auto``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash
from genbacklash_core.guard import CompensationGuard, GuardVerdict
from genbacklash_ros.node.checkpoint import WarmStart
from genbacklash_ros.node.compensate import CompensateStage
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.tracking_stage import TrackingStage

__all__ = ["CompensationJudges", "play_of", "stricter"]


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


def stricter(servo: GuardVerdict, commands: GuardVerdict) -> GuardVerdict:
    """The guard's verdict with the servo modelled: the one of the two yardsticks (the
    model on the modelled servo output, and on the commands) that trusts the model less;
    its reason says which (module notes). A yardstick that has not judged yet does not
    count.

    >>> from genbacklash_core.guard import GuardVerdict
    >>> servo = GuardVerdict(1.0, "on", 0.5, 1.0, 2.0, 100, "compensation on: ...")
    >>> commands = GuardVerdict(0.0, "off", 1.2, 2.4, 2.0, 100, "compensation off: ...")
    >>> v = stricter(servo, commands)
    >>> v.state, v.ratio, v.reason.startswith("on the commands: compensation off")
    ('off', 1.2, True)
    >>> stricter(servo, servo) is servo
    True
    """
    if commands.state == "judging" or commands.trust > servo.trust:
        return servo
    if commands.trust == servo.trust and commands.state == servo.state:
        return servo
    return replace(commands, reason=f"on the commands: {commands.reason}")


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
        The guard on the rows' input (the modelled servo output with a servo modelled).
    command_guard : CompensationGuard
        With a servo modelled, the guard on the commands (module notes); it judges only
        when samples come with their commands.
    tracking : TrackingStage
    await_guard : bool
        The checkpoint's model waits for the guard's first verdict on live samples.
    """

    __slots__ = (
        "_commands",
        "_comp",
        "_guard_off",
        "await_guard",
        "command_guard",
        "guard",
        "tracking",
    )

    def __init__(self, params: NodeParameters, comp: CompensateStage, start: WarmStart) -> None:
        self._comp = comp
        self.guard = CompensationGuard(params.guard_settings())
        self.command_guard = CompensationGuard(params.guard_settings())
        self._commands = False  # samples came with their commands (a servo modelled)
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
        self.command_guard.configure(params.guard_settings())
        self.tracking.judge.configure(params.judge_settings())
        self.apply()

    def judge_samples(
        self,
        us: np.ndarray,
        ys: np.ndarray,
        restarts: np.ndarray,
        model: GeneralBacklash | Cascade | None,
        commands: np.ndarray | None = None,
        command_restarts: np.ndarray | None = None,
    ) -> None:
        """Samples screened for the identifier: does compensating with ``model`` help on
        them (the guard, which fades it if not; ``restarts``: where the drivetrain's path
        since the sample before is not known, the screen's
        :attr:`~genbacklash_ros.node.screen.Screened.restarts`), and the tracking measured on
        every reading since (the judge). ``commands``: with a servo modelled, the commands
        holding at the samples (``us`` the modelled servo output), judged on as well, the
        free run restarting at ``command_restarts`` (``restarts`` when None)."""
        self.guard.update(us, ys, restarts, model)
        if commands is not None:
            self._commands = True
            again = restarts if command_restarts is None else command_restarts
            self.command_guard.update(commands, ys, again, model)
        self.tracking.flush()
        self.apply()

    def adopt(self, model: GeneralBacklash | Cascade | None) -> None:
        """A new model in use: judged at once on the samples the guard remembers."""
        self.guard.adopt(model)
        if self._commands:
            self.command_guard.adopt(model)
        play = play_of(model)
        if play is not None:
            self.tracking.judge.new_model(play)
        self.apply()

    @property
    def verdict(self) -> GuardVerdict:
        """The guard's verdict: with a servo modelled, the stricter of the two yardsticks
        (:func:`stricter`), else the guard's own."""
        if not self._commands:
            return self.guard.verdict
        return stricter(self.guard.verdict, self.command_guard.verdict)

    def flush(self) -> GuardVerdict:
        """Judge the samples the guards have not judged yet; returns :attr:`verdict`."""
        self.guard.flush()
        if self._commands:
            self.command_guard.flush()
        return self.verdict

    def apply(self) -> None:
        """The compensator's trust (the guard's judgement of the model) and share (the
        judge's of the tracking measured)."""
        guard = self.verdict
        self._comp.trust = guard.trust
        off = guard.state == "off"
        if self._guard_off and not off:
            # back after the guard held it off: measured afresh, with a trial (the judge)
            self.tracking.judge.resume()
        self._guard_off = off
        settings = self.guard.settings
        if self.await_guard and (
            self.guard.verdict.samples >= settings.min_samples or not settings.enabled
        ):
            self.await_guard = False
        self._comp.share = 0.0 if self.await_guard else self.tracking.verdict.trust
