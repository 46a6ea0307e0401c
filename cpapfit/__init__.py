"""cpapfit: a personalised CPAP mask cushion from a facial depth scan.

The public API (`cpapfit.api`, loaded on first use so that the command line starts quickly):
`load_scan`, `phantom`, `design`, `evaluate`, `Params` (with `NonrigidParams`, `CushionParams`,
`FitParams`, `QualityParams`, `LandmarkNoise`) and `DesignResult`.
"""

import os

# One OpenBLAS thread (unless the caller says otherwise), set before numpy loads: cpapfit's dense
# arrays are small, and OpenBLAS's idle threads spin, which cost a design ~1.5 s of CPU on 2 cores.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.2.0"
__all__ = ["load_scan", "phantom", "design", "evaluate", "Params", "NonrigidParams", "CushionParams", "FitParams", "QualityParams", "LandmarkNoise", "DesignResult"]


def __getattr__(name: str):
    """The public API's names, from `cpapfit.api` when first asked for."""
    if name in __all__:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'cpapfit' has no attribute {name!r}")
