"""cpapfit: a personalised CPAP mask cushion from a facial depth scan."""

import os

# One OpenBLAS thread (unless the caller says otherwise), set before numpy loads: cpapfit's dense
# arrays are small, and OpenBLAS's idle threads spin, which cost a design ~1.5 s of CPU on 2 cores.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.2.0"
