"""genbacklash_ros: IO, plots and the command line around ``genbacklash_core``.

Later: messages, bag IO, replay, the node and its transports. Nothing here is imported by
the core.
"""

from __future__ import annotations

__all__: list[str] = []
