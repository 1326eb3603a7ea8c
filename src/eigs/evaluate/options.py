"""Options of the ``evaluate`` stage (no heavy imports): :class:`EvaluateOptions` holds every default of the
`evaluate:` config section, built and checked as every stage's options are (``eigs.util.options``); the workflow
passes the keys a config sets as flags (``eigs.plan.evaluate_flags``)."""

from __future__ import annotations

from dataclasses import dataclass

from eigs.util.options import Options


@dataclass(frozen=True)
class EvaluateOptions(Options):
    """``path_frames``: render-path frames (an ellipse for forward-facing captures, else an orbit) scored by BRISQUE
    on scenes without ground truth (E²NeRF's real protocol: 120 path renders beside the blur views).
    ``test_pose_iters``: > 0 scores the second protocol as well, every test camera refined against its image on the
    frozen model for this many iterations (:mod:`eigs.evaluate.test_poses`; 0: today's protocol only)."""

    path_frames: int = 120
    test_pose_iters: int = 0

    def problems(self) -> list[str]:
        out = [] if self.path_frames >= 0 else [f"path_frames must be >= 0, got {self.path_frames}"]
        if self.test_pose_iters < 0:
            out.append(f"test_pose_iters must be >= 0, got {self.test_pose_iters}")
        return out
