"""Measure the peak memory of one ``identify_cascade`` call in this fresh process.

Run by ``bench/speed.py``; imports only numpy and genbacklash_core so that nothing else inflates
the baseline. Prints one JSON object.

    python bench/_memory_child.py DIR {rss,tracemalloc}

``DIR`` holds ``u.npy`` and ``y.npy``.
"""

from __future__ import annotations

import gc
import json
import os
import resource
import sys
import tracemalloc
from pathlib import Path

import numpy as np

from genbacklash_core import identify_cascade


def current_rss() -> int:
    """Resident set size now [bytes] (Linux /proc)."""
    with open("/proc/self/statm", encoding="ascii") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def max_rss() -> int:
    """``ru_maxrss`` in bytes (Linux reports KiB).

    On Linux this is the larger of this address space's peak and a per-process record that
    ``exec`` fills with the peak of the address space it replaces; after ``vfork`` (which
    :mod:`subprocess` uses) that is the *parent's* peak, so it can mask the measurement.
    """
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def peak_rss() -> int:
    """Peak RSS of this address space [bytes] (``VmHWM``, which ``clear_refs`` resets)."""
    with open("/proc/self/status", encoding="ascii") as handle:
        for line in handle:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return max_rss()


def reset_peak() -> bool:
    """Reset the peak RSS (``ru_maxrss``/VmHWM) to the current RSS; Linux >= 4.0."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as handle:
            handle.write("5")
    except OSError:
        return False
    return True


def main() -> None:
    directory, mode = Path(sys.argv[1]), sys.argv[2]
    u = np.load(directory / "u.npy")
    y = np.load(directory / "y.npy")
    gc.collect()
    info: dict[str, object] = {"n": int(u.size)}
    if mode == "rss":
        info["import_peak"] = peak_rss()
        info["ru_maxrss_before"] = max_rss()
        info["reset"] = reset_peak()
        base = current_rss()
        info["base_peak"] = peak_rss()
        result = identify_cascade(u, y, 3, 2, 2)
        info["base"] = base
        info["peak"] = peak_rss()
        info["ru_maxrss_after"] = max_rss()
        info["extra"] = info["peak"] - base
    elif mode == "tracemalloc":
        tracemalloc.start()
        result = identify_cascade(u, y, 3, 2, 2)
        info["extra"] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    else:
        raise SystemExit(f"unknown mode {mode!r}")
    info["converged"] = bool(result.converged)
    print(json.dumps(info))


if __name__ == "__main__":
    main()
