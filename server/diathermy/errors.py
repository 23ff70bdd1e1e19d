"""The exception tree of diathermy; the service maps each class to an HTTP status in one place."""


class DiathermyError(Exception):
    """Base class of every error diathermy raises on purpose."""


class SceneError(DiathermyError, ValueError):
    """A scene (file or object) is invalid or contradictory; the message names the field."""


class MeshError(DiathermyError, ValueError):
    """A grid or mesh request is invalid (too small, too large, non-positive spacing)."""


class SolverDivergedError(DiathermyError, RuntimeError):
    """A linear or nonlinear solve did not reach its tolerance; never return its garbage."""

    def __init__(self, message: str, *, iterations: int = 0, residual: float = float("nan")):
        super().__init__(message)
        self.iterations = iterations
        self.residual = residual


class CheckpointError(DiathermyError, ValueError):
    """A checkpoint, run file or dataset is corrupt, foreign or does not match the scene."""
