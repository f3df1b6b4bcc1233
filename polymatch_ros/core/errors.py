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
    """A fixed-step explicit method asked to run beyond its linear stability limit."""

    exit_code = 2


class ParameterError(PolymatchError):
    """A bad ROS parameter or command-line value."""

    exit_code = 2
