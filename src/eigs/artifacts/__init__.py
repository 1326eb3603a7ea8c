"""Every file format that passes between stages, read and written only here: the EDI result (:mod:`.edi`), the
latent poses and test cameras of SfM (:mod:`.poses`), the Gaussian cloud as a 3DGS PLY (:mod:`.gaussians`).
The scene file has its own package (:mod:`eigs.scene`)."""
