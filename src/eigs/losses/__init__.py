"""Training losses shared by the methods: photometric (L1 + D-SSIM); the event-integration and motion-consistency
losses of EiGS join here."""

from eigs.losses.photometric import photometric_loss

__all__ = ["photometric_loss"]
