"""The mark genbacklash leaves in every bag directory it writes.

``--overwrite`` (:mod:`genbacklash_ros.cli.paths`) removes a directory only when it holds
this file and nothing but the bag's own files: a recording, or anything else a user keeps
there, is never taken for an earlier run's output.
"""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["OUTPUT_MARKER", "mark_output"]

#: The file's name inside the bag directory (rosbag2 readers ignore files that
#: ``metadata.yaml`` does not list).
OUTPUT_MARKER = "genbacklash-output.json"


def mark_output(directory: str | Path) -> None:
    """Write :data:`OUTPUT_MARKER` into a bag directory genbacklash has just created.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> mark_output(folder)
    >>> (folder / OUTPUT_MARKER).is_file()
    True
    """
    from genbacklash_core import __version__

    text = json.dumps({"written_by": "genbacklash", "version": __version__})
    (Path(directory) / OUTPUT_MARKER).write_text(text + "\n")
