"""Processes seen through Linux ``/proc``: a process's children, and whether one still runs
(the identify process of ``thread_priority``, checked by the node, transport and shutdown
tests)."""

from __future__ import annotations

from pathlib import Path


def children(pid: int) -> tuple[int, ...]:
    """The processes whose parent is ``pid``."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return tuple(found)


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"
