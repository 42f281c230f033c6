"""The ``genbacklash`` command line: one module per subcommand group.

Every command runs numpy's BLAS on one thread (:mod:`genbacklash_ros.blas_threads`). OpenBLAS
starts a thread per core when numpy loads it, before that limit is set; told here, before any
of the command line's modules imports numpy, it starts none. Nothing is computed differently
(the limit is one thread either way): the process is spared the threads' start and spin,
~0.05 s of CPU at each command's start (BENCHMARKS.md "Replay throughput"). A value the
environment sets already is kept, and processes the command starts inherit it.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
