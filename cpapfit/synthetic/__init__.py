"""Synthetic subjects with ground truth: faces made, posed before a virtual depth camera and rendered.

`camera.py` the camera, its sensor and the capture (`Phantom`); `template_phantom.py` faces made
from the template, `mouth.py` opening their mouths, `skin.py` their colours, `glasses.py` a frame
worn on them; `ict_phantom.py` and `ict_sweep.py` faces of the ICT model (`cpapfit.ict`) as
captures, head meshes and sweeps; `defects.py` captures made faulty; `accuracy.py` distances
against the truth. The stages never import this package (`tests/test_layout.py`).
"""
