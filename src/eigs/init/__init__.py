"""Gaussian initialisation (``eigs init``): the 3DGS initial cloud from the SfM points and random Gaussians in the
scene bounds (:mod:`eigs.init.initialize`), its options (:mod:`eigs.init.options`) and CLI (:mod:`eigs.init.cli`).
Reads the SfM output as an artifact (:mod:`eigs.artifacts.colmap`); writes ``init.ply``
(:mod:`eigs.artifacts.gaussians`).
"""
