"""The live demo's verdict: did compensation make tracking worse, beyond the comparison's spread?

The demo compares the arm (on the node's compensated commands) with an uncompensated twin (on
the desired commands, taken at the same moments). That comparison is fair only while the two
drivetrains would take the same path on the same commands. A load that coasts into the play
does not: once anything has moved the arm's load elsewhere in the play (a trial of a second),
the arm and its twin take identical commands for the rest of the run and still track
differently, by up to 20 % a second either way (BENCHMARKS.md, the live demo, 2026-11-28:
a run cut -7 % with compensation off for all but 2 s of its second half). The demo's old
warning then blamed compensation for a half in which it was off.

So the arm carries a second uncompensated twin whose load starts elsewhere in the play
(:data:`~genbacklash_ros.demo.arm.PERTURB` of it away) and which then takes exactly the
first twin's commands: the cut of that *perturbed twin* against the first twin over the same
readings is what the comparison spreads with no compensation at all. Harm is called only
where the arm's cut is below ``-HARM`` *and* below minus that spread, over either of

* the second half (the cut the demo always reported, reported still), or
* the readings while the arm held a command that differed from the desired one, and
  :data:`SETTLE_S` after (the windows in which compensation acted,
  trials included: ``acted``).

A cut below ``-HARM`` within the spread is printed with that explanation, never hidden.

Examples
--------
>>> half = Comparison(arm=0.0298, twin=0.0278, perturbed=0.0301, seconds=20.0)
>>> round(half.cut, 3), round(half.spread, 3), half.harmful
(-0.072, 0.083, False)
>>> Comparison(arm=0.036, twin=0.030, perturbed=0.0303, seconds=2.0).harmful
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["HARM", "SETTLE_S", "Comparison", "DemoVerdict"]

HARM = 0.02
"""A cut below minus this share (and below minus the spread) is harm: the first rule's
margin the benchmarks use."""

SETTLE_S = 1.0
"""Seconds after the last command that differed from the desired one that still count as
compensation acting (the load settling from it)."""


@dataclass(frozen=True)
class Comparison:
    """RMS load tracking errors over one set of readings (rad; NaN: no readings).

    Attributes
    ----------
    arm, twin, perturbed : float
        The arm on the compensated commands, its uncompensated twin, and the perturbed
        uncompensated twin (module notes).
    seconds : float
        Seconds of readings the errors are taken over.
    """

    arm: float
    twin: float
    perturbed: float
    seconds: float

    @property
    def cut(self) -> float:
        """``1 - arm / twin``: what compensation cut (negative: worse); NaN without readings."""
        return 1.0 - self.arm / self.twin if self.twin > 0.0 else math.nan

    @property
    def spread(self) -> float:
        """``|1 - perturbed / twin|``: what the comparison differs by with no compensation."""
        return abs(1.0 - self.perturbed / self.twin) if self.twin > 0.0 else math.nan

    @property
    def harmful(self) -> bool:
        """The arm tracked worse than its twin by more than ``HARM`` and than the spread."""
        cut, spread = self.cut, self.spread
        if not (math.isfinite(cut) and math.isfinite(spread)):
            return False
        return cut < -max(HARM, spread)


@dataclass(frozen=True)
class DemoVerdict:
    """One joint's verdict, on two sets of its readings (module notes): harm on either is
    harm.

    Attributes
    ----------
    half : Comparison
        Over the second half of the run.
    acted : Comparison
        Over the readings while compensation acted (and :data:`SETTLE_S` after), the whole
        run.
    """

    half: Comparison
    acted: Comparison

    @property
    def worse(self) -> bool:
        """Compensation made tracking worse: harm over the second half or where it acted."""
        return self.half.harmful or self.acted.harmful

    def explain(self, joint: str) -> str | None:
        """A line for ``joint``: the warning of harm, or the explanation of a cut below
        ``-HARM`` within the spread; None when neither applies.

        >>> half = Comparison(0.0298, 0.0278, 0.0301, 20.0)
        >>> acted = Comparison(math.nan, math.nan, math.nan, 0.0)
        >>> print(DemoVerdict(half, acted).explain("joint_1"))  # doctest: +NORMALIZE_WHITESPACE
        note: joint_1 tracked 7.2 % worse than its twin over the second half, within the
        8.3 % by which two uncompensated twins differ on the same commands (a load that
        coasts in the play parts from its twin once it sits elsewhere in it); no command
        differed from the desired one in this run
        """
        half, acted = self.half, self.acted
        if acted.seconds > 0.0:
            then = (
                f"compensation acted over {acted.seconds:.1f} s of readings (commands that "
                f"differed from the desired ones, and {SETTLE_S:g} s after each): cut "
                f"{_pct(acted.cut)} there, twins {_pct(acted.spread)} apart"
            )
        else:
            then = "no command differed from the desired one in this run"
        if self.worse:
            return (
                f"WARNING: compensation made tracking worse on {joint}: cut {_pct(half.cut)} "
                f"over the second half (uncompensated twins {_pct(half.spread)} apart); "
                f"{then}; please report it with this output"
            )
        if math.isfinite(half.cut) and half.cut < -HARM:
            return (
                f"note: {joint} tracked {_pct(-half.cut)} worse than its twin over the second "
                f"half, within the {_pct(half.spread)} by which two uncompensated twins differ "
                "on the same commands (a load that coasts in the play parts from its twin once "
                f"it sits elsewhere in it); {then}"
            )
        return None


def _pct(share: float) -> str:
    return "n/a" if not math.isfinite(share) else f"{100 * share:.1f} %"
