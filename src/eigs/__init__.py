"""eigs: event-informed 3D Gaussian Splatting from event streams and motion-blurred frames."""

__version__ = "0.1.0"
