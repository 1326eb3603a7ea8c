"""Every file format that passes between stages, read and written only here: the EDI result (:mod:`.edi`), the
latent poses and test cameras of SfM (:mod:`.poses`), the COLMAP model's points (:mod:`.colmap`), the Gaussian
cloud as a 3DGS PLY (:mod:`.gaussians`), the radiance field (:mod:`.field`), a run's motion (:mod:`.motion`) and the
run folder's layout (:mod:`.run`).
The scene file has its own package (:mod:`eigs.scene`)."""
