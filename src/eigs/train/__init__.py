"""Training: the Gaussian model, densification, the method catalog (catalog.py) and the loop shared by every method.

Reads only the stage artifacts (``eigs.artifacts``), the scene file (``eigs.scene``) and the libraries ``render``,
``metrics``, ``losses`` and ``util``; see docs/training.md.
"""
