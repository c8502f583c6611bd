"""Exceptions raised by warpspec.

``InputError`` is anything wrong with what the user gave (an argument, a device, a resolution
the memory cannot hold, a file); ``SceneError`` narrows it to a field of the scene. Both are
``ValueError`` subclasses whose message is one line naming the field and the fix; the command
line turns them into exit status 2. ``ReconstructionError`` is a run that failed for another
reason (a non-finite level set, no surface); exit status 1.
"""

__all__ = ["InputError", "ReconstructionError", "SceneError"]


class InputError(ValueError):
    """Invalid input: an argument, a device, a resolution, a memory limit or a file.

    The message is one line that names the field, the value and what is expected.
    """


class SceneError(InputError):
    """Invalid input in a scene field (or, historically, any input: catch ``InputError``)."""


class ReconstructionError(RuntimeError):
    """The solver could not continue (a non-finite value, an empty surface)."""
