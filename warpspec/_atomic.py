"""Writing files safely: the one atomic-write helper of the package, and the path checks.

Every file warpspec writes goes to a unique temporary file in the target's folder
(``tempfile.mkstemp``: a short hidden name, so any legal target name works, and no two writers
share one) and is renamed onto the target only when complete. Temporary files still alive are
tracked, so that a signal handler can remove them before the process exits.
"""

from __future__ import annotations

import contextlib
import glob
import os
import signal
import tempfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from .errors import InputError

__all__ = [
    "StagedOutputs",
    "Terminated",
    "WriteError",
    "atomic_write",
    "check_paths",
    "install_signal_cleanup",
    "remove_live_temps",
    "restore_signals",
    "same_file",
    "temp_beside",
]

_LIVE: set[str] = set()
WRITTEN: list[Path] = []
"""Every file renamed into place by this process (the command line clears it per command)."""


class Terminated(KeyboardInterrupt):
    """Raised in the main thread when the process receives SIGTERM (exit status 143)."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"signal {signum}")
        self.signum = signum


def _read_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _read_umask()  # read once: os.umask is process-wide and writers may run in threads


def temp_beside(path: str | os.PathLike) -> Path:
    """Create a unique, empty temporary file next to ``path``, keeping its extension.

    The name is short (``.ws`` and 8 random characters plus the extension) whatever the
    length of ``path``'s name. Its mode follows the umask, as a new file's would.
    """
    path = Path(path)
    suffix = path.suffix if len(path.suffix) <= 16 else ""
    fd, name = tempfile.mkstemp(prefix=".ws", suffix=suffix, dir=path.parent or ".")
    os.close(fd)
    _LIVE.add(name)
    with contextlib.suppress(OSError):
        os.chmod(name, 0o666 & ~_UMASK)
    return Path(name)


def discard_temp(tmp: str | os.PathLike) -> None:
    """Remove a temporary file and anything a writer derived from its name (``tmp.npz``...)."""
    name = os.fspath(tmp)
    for other in [name, *glob.glob(glob.escape(name) + "?*")]:
        with contextlib.suppress(OSError):
            os.unlink(other)
    _LIVE.discard(name)


def remove_live_temps() -> None:
    """Remove every temporary file this process still holds (signal handlers, exits)."""
    for name in list(_LIVE):
        discard_temp(name)


def _renamed(tmp: Path, path: Path) -> None:
    os.replace(tmp, path)
    _LIVE.discard(os.fspath(tmp))
    WRITTEN.append(path)


class WriteError(OSError):
    """A file could not be written; ``filename`` is the target, not the temporary file."""

    def __str__(self) -> str:
        return f"cannot write {self.filename!r}: {self.strerror}"


def _as_oserror(exc: OSError, path: Path) -> WriteError:
    """The same error, naming the target instead of the temporary file."""
    return WriteError(exc.errno, exc.strerror or str(exc), os.fspath(path))


def atomic_write(path: str | os.PathLike, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it onto ``path``.

    On any failure or interruption the temporary file is removed and a file already at
    ``path`` is left as it was.

    Raises:
        WriteError: If the file cannot be written (an ``OSError``; ``filename`` is ``path``).
    """
    path = Path(path)
    try:
        tmp = temp_beside(path)
    except OSError as exc:
        raise _as_oserror(exc, path) from None
    try:
        write(tmp)
        _renamed(tmp, path)
    except OSError as exc:
        raise _as_oserror(exc, path) from None
    finally:
        discard_temp(tmp)


class StagedOutputs:
    """Several outputs written to temporary files, then renamed together (or all discarded).

    Use as a context manager: leaving it without :meth:`commit` (an error, an interrupt)
    removes every temporary file.
    """

    def __init__(self) -> None:
        self.staged: list[tuple[Path, Path]] = []
        self.committed: list[Path] = []

    def stage(self, path: str | os.PathLike, write: Callable[[Path], object]) -> None:
        """Write one output to its temporary file now.

        Raises:
            OSError: If it cannot be written; its ``filename`` is ``path``.
        """
        path = Path(path)
        try:
            tmp = temp_beside(path)
        except OSError as exc:
            raise _as_oserror(exc, path) from None
        self.staged.append((tmp, path))
        try:
            write(tmp)
        except OSError as exc:
            raise _as_oserror(exc, path) from None

    def commit(self) -> None:
        """Rename every staged file onto its target."""
        while self.staged:
            tmp, path = self.staged[0]
            try:
                _renamed(tmp, path)
            except OSError as exc:
                raise _as_oserror(exc, path) from None
            self.staged.pop(0)
            self.committed.append(path)

    def discard(self) -> None:
        """Remove every temporary file not yet renamed."""
        for tmp, _ in self.staged:
            discard_temp(tmp)
        self.staged.clear()

    def __enter__(self) -> StagedOutputs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.discard()


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: the same resolved path, or the same inode (links)."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_paths(
    outputs: Mapping[str, Path | None], inputs: Mapping[str, Path | None] | None = None
) -> None:
    """Refuse an output that is also an input or another output (hard links included).

    Args:
        outputs: Flag -> path of each file to be written (``None`` entries are skipped).
        inputs: Flag -> path of each file to be read.

    Raises:
        InputError: Naming the output's flag and the other use of the file.
    """
    outs = [(f, Path(p)) for f, p in outputs.items() if p is not None]
    ins = [(f, Path(p)) for f, p in (inputs or {}).items() if p is not None]
    for n, (flag, path) in enumerate(outs):
        for other, src in ins:
            if same_file(path, src):
                raise InputError(f"{flag}: {str(path)!r} is the input file of {other}; "
                                 "writing it would destroy the input, choose another name")
        for other, dst in outs[:n]:
            if same_file(path, dst):
                raise InputError(f"{flag}: {str(path)!r} is also the file of {other}; "
                                 "choose another name")


def _on_signal(signum: int, frame: object) -> None:
    remove_live_temps()
    raise Terminated(signum)


def install_signal_cleanup(signals: Iterable[int] = (signal.SIGTERM,)) -> dict[int, object]:
    """On these signals, remove the live temporary files and raise :class:`Terminated`.

    The exception unwinds through the writers' cleanup, so the command line can report the
    interruption and exit with ``128 + signum``. Only possible in the main thread; elsewhere
    this does nothing.

    Returns:
        The previous handlers, for :func:`restore_signals`.
    """
    previous = {}
    for signum in signals:
        with contextlib.suppress(ValueError, OSError):
            previous[signum] = signal.signal(signum, _on_signal)
    return previous


def restore_signals(previous: Mapping[int, object]) -> None:
    """Put back the handlers :func:`install_signal_cleanup` replaced."""
    for signum, handler in previous.items():
        with contextlib.suppress(ValueError, OSError, TypeError):
            signal.signal(signum, handler)


def check_size(path: str | os.PathLike, limit: int, field: str) -> int:
    """The size of file ``path`` in bytes, refused before reading when above ``limit``.

    Raises:
        InputError: If the file is larger than ``limit`` (the message names both sizes).
    """
    try:
        size = os.stat(path).st_size
    except OSError:
        return 0  # the reader reports a missing or unreadable file in its own words
    if size > limit:
        raise InputError(f"{field}: {os.fspath(path)!r} is {size / 2**20:.1f} MiB, above the "
                         f"limit of {limit / 2**20:.0f} MiB for this kind of file; "
                         "check that it is the right file")
    return size
