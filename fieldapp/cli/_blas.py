"""OpenBLAS on one thread in every ``fieldapp`` process, set before numpy loads it.

numpy's OpenBLAS starts a thread per core for any product larger than a few thousand
elements, and its threads busy-wait for more work after each one. fieldapp's products are
(N, 3) points by 3 x 3 rotations or by a few plane normals: memory-bound, no faster on two
threads, and the waiting thread burnt as much CPU as the work (levelling 0.26 -> 0.15 s CPU,
filtering 0.36 -> 0.10 s on a 3 x 3 plot, issue 22). The reconstruction's parallel work has
its own threads (``reconstruction.threads``). Child processes (the GUI's reconstruction,
local batch workers) inherit the setting; a value already in the environment is kept.

numpy's own huge pages are off too (``NUMPY_MADVISE_HUGEPAGE=0``, read when numpy loads): it
asks the kernel to back every array of 4 MB or more with 2 MB pages, and on a machine whose
memory is full of page cache each fresh one is compacted for, synchronously: 0.3-0.4 s of
system time in the outlier removal alone, 1.2-1.4 s -> 0.6-0.7 s for a whole 3 x 3 run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
