"""OpenBLAS on one thread in every ``fieldapp`` process, set before numpy loads it.

numpy's OpenBLAS starts a thread per core for any product larger than a few thousand
elements, and its threads busy-wait for more work after each one. fieldapp's products are
(N, 3) points by 3 x 3 rotations or by a few plane normals: memory-bound, no faster on two
threads, and the waiting thread burnt as much CPU as the work (levelling 0.26 -> 0.15 s CPU,
filtering 0.36 -> 0.10 s on a 3 x 3 plot, issue 22). The reconstruction's parallel work has
its own threads (``reconstruction.threads``). Child processes (the GUI's reconstruction,
local batch workers) inherit the setting; a value already in the environment is kept.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
