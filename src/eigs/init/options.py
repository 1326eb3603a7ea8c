"""Options of the ``init`` stage: :class:`InitOptions` holds every default; the config schema, the rule and the CLI
take theirs from here (see ``eigs.util.options``). No heavy imports: the CLI reads it for its help text."""

from __future__ import annotations

from dataclasses import dataclass, fields


@dataclass
class InitOptions:
    """``min_points``: with fewer SfM points, ``random`` random Gaussians are added in the scene bounds;
    ``sh_degree``: spherical-harmonics degree of the colours; ``seed``: of the random Gaussians."""

    min_points: int = 1000
    random: int = 10_000
    sh_degree: int = 3
    seed: int = 0


INIT_CONFIG_KEYS = tuple(f.name for f in fields(InitOptions))
