"""Plots of identification results (matplotlib, Agg backend; the core stays plot-free)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
    IdentificationResult,
    IterationHistory,
)
from genbacklash_core.cascade import backlash_of

__all__ = [
    "parameter_unit",
    "plot_characteristic",
    "plot_history",
    "save_identification_plots",
]

_SUPERSCRIPTS = "\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079"


def parameter_unit(name: str, unit: str = "rad") -> str:
    """The unit of a model parameter when positions are in ``unit`` (``""``: none): a branch
    is ``sum_k m_k (u + c)^k`` (eqs. 11-12), so ``m_k`` is in unit^(1-k); ``c_*`` in the
    unit; the linear block's ``a_i``, ``b_j`` are dimensionless ("1").

    >>> [parameter_unit(n) for n in ("m_left_1", "m_left_3", "c_right", "b_1")]
    ['rad/rad', '1/rad\u00b2', 'rad', '1']
    """
    if name.startswith(("a_", "b_")):
        return "1"
    if not unit:
        return ""
    if name.startswith("c_"):
        return unit
    if name.startswith(("m_left_", "m_right_")):
        k = int(name.rsplit("_", 1)[1])
        power = "".join(_SUPERSCRIPTS[int(c)] for c in str(k - 1))
        return {1: f"{unit}/{unit}", 2: f"1/{unit}"}.get(k, f"1/{unit}{power}")
    return ""


def _with_unit(label: str, unit: str) -> str:
    return f"{label} [{unit}]" if unit else f"{label} (in the data's units)"


def plot_characteristic(
    estimate: GeneralBacklash | Cascade,
    u_range: tuple[float, float],
    truth: GeneralBacklash | Cascade | None = None,
    data: tuple[np.ndarray, np.ndarray] | None = None,
    unit: str = "rad",
) -> Figure:
    """The two branches of the estimate (and the truth) over ``u_range``, like Figs. 3, 5, 8, 11.

    ``data`` is an optional ``(u, x)`` scatter of measured backlash outputs; ``unit`` the
    unit of the positions (``""``: none, as in the paper's examples).
    """
    u = np.linspace(u_range[0], u_range[1], 400)
    fig, ax = plt.subplots(figsize=(6.4, 5.2), layout="constrained")
    if data is not None:
        ax.plot(data[0], data[1], ".", color="0.75", markersize=2, label="measured", zorder=1)
    est = backlash_of(estimate)
    ax.plot(u, est.left(u), color="C0", label="estimate: left branch L(u)")
    ax.plot(u, est.right(u), color="C1", label="estimate: right branch R(u)")
    if truth is not None:
        tru = backlash_of(truth)
        ax.plot(u, tru.left(u), "--", color="k", linewidth=1, label="truth")
        ax.plot(u, tru.right(u), "--", color="k", linewidth=1)
    ax.set_xlabel(_with_unit("input u", unit))
    ax.set_ylabel(_with_unit("backlash output x", unit))
    ax.set_title("General backlash characteristic")
    ax.grid(True, alpha=0.3)
    # below the axes: inside, it covered the branches' ends
    fig.legend(loc="outside lower center", ncol=2, fontsize="small")
    return fig


def plot_history(
    history: IterationHistory, truth: np.ndarray | None = None, unit: str = "rad"
) -> Figure:
    """Parameter estimates per iteration (the paper's Figs. 4, 6, 9, 10, 12).

    ``truth``, in the order of ``history.names``, draws each true value as a dotted line;
    each name in the legend carries its unit (``unit``: that of the positions).
    """
    names = history.names
    linear = [i for i, n in enumerate(names) if n.startswith(("a_", "b_"))]
    backlash = [i for i in range(len(names)) if i not in linear]
    panels = [backlash] + ([linear] if linear else [])
    fig, axes = plt.subplots(
        1, len(panels), figsize=(6.4 * len(panels), 5.4), squeeze=False, layout="constrained"
    )
    steps = np.arange(history.values.shape[0])
    titles = ["Backlash parameter estimates", "Linear block parameter estimates"]
    for ax, indices, title in zip(axes[0], panels, titles, strict=False):
        for k, i in enumerate(indices):
            color = f"C{k % 10}"
            part = parameter_unit(names[i], unit)
            label = f"{names[i]} [{part}]" if part else names[i]
            ax.plot(steps, history.values[:, i], "o-", color=color, markersize=3, label=label)
            if truth is not None:
                ax.axhline(truth[i], color=color, linestyle=":", linewidth=1)
        ax.set_xlabel("iteration")
        ax.set_ylabel(
            "estimate (unit per parameter: see the legend)"
            if unit or indices == linear
            else "estimate (the data carry no unit)"
        )
        ax.set_title(title + ("; dotted: truth" if truth is not None else ""))
        ax.grid(True, alpha=0.3)
        # below the panel, so that no curve hides behind it
        longest = max((len(t.get_text()) for t in ax.legend().get_texts()), default=0)
        ax.legend(
            loc="upper center",
            bbox_to_anchor=(0.5, -0.14),
            fontsize="x-small",
            ncol=4 if longest <= 22 else 2,
        )
    return fig


def save_identification_plots(
    result: IdentificationResult,
    out_dir: str | Path,
    u: np.ndarray,
    y: np.ndarray,
    truth: GeneralBacklash | Cascade | None = None,
    unit: str = "rad",
) -> list[Path]:
    """Write ``characteristic.png`` and ``history.png`` into ``out_dir``; return the paths
    (``unit``: that of the positions, ``""`` for none)."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    span = (float(np.min(u)), float(np.max(u)))
    data = None if isinstance(result.model, Cascade) else (u, y)
    written = []
    fig = plot_characteristic(result.model, span, truth, data, unit)
    written.append(directory / "characteristic.png")
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)
    truth_values = truth.parameters() if truth is not None else None
    fig = plot_history(result.history, truth_values, unit)
    written.append(directory / "history.png")
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)
    return written
