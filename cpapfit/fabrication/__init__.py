"""Fabrication: the printable files checked as written (`files.py`), the casting mould (`mould.py`,
its parting surfaces `parting.py`, its draft `draft.py`) and the frame the cushion fits into
(`frame.py`, its vents `vents.py`, the dead space `dead_space.py`)."""
