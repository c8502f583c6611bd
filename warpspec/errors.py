"""Exceptions raised by warpspec."""

__all__ = ["SceneError", "ReconstructionError"]


class SceneError(ValueError):
    """Invalid input: a scene field, an argument or a file.

    The message is one line that names the field, the value and what is expected.
    """


class ReconstructionError(RuntimeError):
    """The solver could not continue (a non-finite value, an empty surface)."""
