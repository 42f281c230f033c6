"""The exit codes of every ``genbacklash`` command (GUIDE §4).

>>> EXIT_OK, EXIT_BAD_INPUT, EXIT_NOT_CONVERGED
(0, 2, 3)
"""

from __future__ import annotations

__all__ = ["EXIT_BAD_INPUT", "EXIT_BROKEN_PIPE", "EXIT_LOST", "EXIT_NOT_CONVERGED", "EXIT_OK"]

EXIT_OK = 0
"""Success."""
EXIT_LOST = 1
"""``fleet``: the cluster lost bags (re-run to retry them); the other rows are stored."""
EXIT_BAD_INPUT = 2
"""Bad input or options: a one-line reason on stderr."""
EXIT_NOT_CONVERGED = 3
"""The identifier ran but did not converge (the result, with its reason, is still printed)."""
EXIT_BROKEN_PIPE = 141
"""128 + SIGPIPE, what a shell reports for a writer killed by it."""
