"""Errors that reach the user as one line and an exit code."""


class PolymatchError(Exception):
    """A user-facing error: printed as one line, exits with ``exit_code``.

    The message should name what is wrong and where (a scene key path, a
    polytope index, a parameter), never a Python traceback.
    """

    exit_code = 1


class SceneError(PolymatchError):
    """An invalid scene file or value; the message starts with the key path."""

    exit_code = 2


class ShapeError(SceneError):
    """Vertex data that cannot be decomposed (reflected, not congruent, degenerate, ...)."""


class StabilityError(PolymatchError):
    """A fixed-step method refused for a scene: beyond its linear stability limit, no stable
    step at all (``limit == 0``), the wrong model order, or an unknown method name.

    The message is for people; readers use the fields: ``method`` (name), ``dt`` (the step
    asked for), ``limit`` (the largest stable step, 0 when there is none, None when the
    refusal is not about stability) and ``cause`` (what makes the scene stiff).
    """

    exit_code = 2

    def __init__(self, message: str, *, method: str | None = None, dt: float | None = None,
                 limit: float | None = None, cause: str | None = None) -> None:
        super().__init__(message)
        self.method, self.dt, self.limit, self.cause = method, dt, limit, cause


class StepLimitError(PolymatchError):
    """An adaptive run used up integrator.max_steps (accepted + rejected steps) before t_end."""


class ParameterError(PolymatchError):
    """A bad ROS parameter or command-line value."""

    exit_code = 2
