"""Is the scan good enough for the mask designed on it: the gates (`gates.py`) and what they measure,
the face's proportions (`proportions.py`) and what stands in front of it (`in_front.py`). Their
thresholds are `cpapfit.thresholds.QualityParams`."""
