"""Camera poses: COLMAP (pycolmap) on the EDI latent frames, or known poses with triangulation only, one canonical
frame, test cameras and the Sim(3) accuracy report.

Modules: :mod:`~eigs.sfm.colmap` (pycolmap wrapper), :mod:`~eigs.sfm.given` (fixed-pose triangulation),
:mod:`~eigs.sfm.canonical`, :mod:`~eigs.sfm.register` (test cameras); the Sim(3) alignment and ATE it reports with
are :mod:`eigs.metrics.trajectory`'s. The artifacts it writes (the COLMAP model, ``poses.h5``,
``test_cameras.h5``) are defined in :mod:`eigs.artifacts`; the Gaussian initialisation that reads them is the next
stage, :mod:`eigs.init`. See docs/sfm.md.
"""
