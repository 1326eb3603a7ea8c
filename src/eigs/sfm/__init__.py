"""Camera poses and initial Gaussians: COLMAP (pycolmap) on the EDI latent frames or known poses with
triangulation only, one canonical frame, test cameras, Sim(3) accuracy report and the 3DGS initialization PLY.

Modules: :mod:`~eigs.sfm.colmap` (pycolmap wrapper), :mod:`~eigs.sfm.given` (fixed-pose triangulation),
:mod:`~eigs.sfm.canonical`, :mod:`~eigs.sfm.register` (test cameras), :mod:`~eigs.sfm.align` (Sim(3), ATE),
:mod:`~eigs.sfm.init` (Gaussian initialization). The artifacts it writes (``poses.h5``, ``test_cameras.h5``, the PLY)
are defined in :mod:`eigs.artifacts`. See docs/sfm.md.
"""
