"""Options of the ``init`` stage: :class:`InitOptions` holds every default; the config schema, the rule and the CLI
take theirs from here (built and checked as every stage's options are, ``eigs.util.options``). No heavy imports: the
CLI reads it for its help text."""

from __future__ import annotations

from dataclasses import dataclass

from eigs.util.options import Options


@dataclass(frozen=True)
class InitOptions(Options):
    """``min_points``: with fewer SfM points, ``random`` random Gaussians are added in the scene bounds;
    ``sh_degree``: spherical-harmonics degree of the colours; ``seed``: of the random Gaussians."""

    min_points: int = 1000
    random: int = 10_000
    sh_degree: int = 3
    seed: int = 0
