"""Outputs that never destroy data: one file written atomically, several files written as one,
SIGTERM as a clean stop, and the leftovers of runs that were killed.

:func:`write_atomically` writes one file through a temporary file beside it and renames it
into place, so an interrupted write never leaves half a file.

A command that writes several files (a track, its TUM copy, a figure) writes each one to a
hidden temporary file beside its target and moves them all into place only once every one is
written (:class:`OutputSet`): an error, Ctrl-C or SIGTERM on the way leaves no new file and
every existing one as it was. :func:`sigterm_exits` makes SIGTERM unwind the stack like Ctrl-C
(so the clean-ups in ``finally`` and ``except`` run) and end the process with status 143.
:func:`remove_stale_partials` removes the hidden ``.NAME.partial-PID`` folders of processes
that no longer exist. This module imports nothing of tangraph's, so every writer can use it;
a track's set of outputs is :func:`tangraph.track_outputs.write_track_outputs`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = [
    "OutputSet",
    "Terminated",
    "deferred_signals",
    "remove_stale_partials",
    "sigterm_exits",
    "write_atomically",
]

log = logging.getLogger(__name__)

SIGTERM_STATUS = 128 + int(signal.SIGTERM)  # 143, the shell's status of a process ended by SIGTERM


class Terminated(SystemExit):
    """Raised by the SIGTERM handler of :func:`sigterm_exits`; exits with status 143."""

    def __init__(self) -> None:
        super().__init__(SIGTERM_STATUS)


def _raise_terminated(signum, frame) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_exits() -> Iterator[None]:
    """While active, SIGTERM raises :class:`Terminated` (a ``SystemExit`` with status 143).

    The stack then unwinds as after Ctrl-C, so temporary files and folders are removed by the
    code that made them. Only the main thread can take signals, and a handler the program set
    itself (or SIG_IGN) is left alone: elsewhere this does nothing. The previous handler comes
    back on exit.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)
    if previous is not signal.SIG_DFL:
        yield
        return
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back for the few renames that put outputs in place: a signal
    that comes meanwhile is noted and raised again, with the handler it would have met, once
    the block is done, never between two renames. Does nothing outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held = [s for s in (signal.SIGINT, signal.SIGTERM) if signal.getsignal(s) is not None]
    previous = {s: signal.getsignal(s) for s in held}
    came: list[int] = []
    for s in held:
        signal.signal(s, lambda signum, frame: came.append(signum))
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for signum in dict.fromkeys(came):
            signal.raise_signal(signum)


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (on this machine); unsure counts as alive."""
    if pid <= 0:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # it exists but is not ours, or we cannot tell
        return True
    return True


def remove_stale_partials(target: str | os.PathLike) -> list[Path]:
    """Remove ``.NAME.partial-PID`` beside ``target`` (named NAME) whose process has ended.

    Also the temporary files of :class:`OutputSet` (``.STEM.partial-PID-XXXX.SUFFIX``). The
    folder or file of a process that still runs, and this process's own, are kept. A stale
    ``.NAME.old-PID`` or ``.STEM.old-PID-XXXX`` (the previous version kept while a new one is
    renamed into place) goes too, but only while ``target`` itself exists: otherwise it may be
    the one copy left. Returns what was removed.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> (folder / ".demo.partial-999999999").mkdir()
    >>> [p.name for p in remove_stale_partials(folder / "demo")]
    ['.demo.partial-999999999']
    """
    target = Path(target)
    name, stem, suffix = (re.escape(t) for t in (target.name, target.stem, target.suffix))
    pattern = re.compile(
        rf"^(?:\.{name}\.(partial|old)-(\d+)|\.{stem}\.(partial|old)-(\d+)-[A-Za-z0-9_]+{suffix})$"
    )
    removed: list[Path] = []
    try:
        entries = list(target.parent.iterdir())
    except FileNotFoundError:
        return removed
    for entry in entries:
        match = pattern.match(entry.name)
        if match is None:
            continue
        kind, pid = (match.group(1), match.group(2)) if match.group(1) else (match.group(3), match.group(4))
        pid = int(pid)
        if pid == os.getpid() or _alive(pid) or (kind == "old" and not target.exists()):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        if not entry.exists():
            log.info("removed %s, left by process %d that no longer runs", entry, pid)
            removed.append(entry)
    return removed


def write_atomically(path: Path, overwrite: bool, write: Callable[[Path], object]) -> None:
    """Write through a temporary file in the same folder, then rename: never a half file."""
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a written file gets the usual mode
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _file_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


class OutputSet:
    """Write several files as one: all of them appear, or none does.

    :meth:`path` gives, for each target, a temporary file in the target's folder (hidden, with
    the target's suffix so that writers that read the format from it still work); write there.
    When the ``with`` block ends normally every temporary file is renamed onto its target; on
    an exception, Ctrl-C or :class:`Terminated` they are all removed and no target is touched.
    A target that exists is refused (``FileExistsError``) unless ``overwrite``; if a rename
    fails part-way, the targets already replaced get their old contents back.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> with OutputSet() as outputs:
    ...     outputs.path(folder / "a.txt").write_text("a")
    ...     outputs.path(folder / "b.txt").write_text("b")
    1
    1
    >>> sorted(p.name for p in folder.iterdir())
    ['a.txt', 'b.txt']
    """

    def __init__(self, *, overwrite: bool = False) -> None:
        self.overwrite = overwrite
        self._pending: dict[Path, Path] = {}  # target -> temporary file

    def path(self, target: str | os.PathLike) -> Path:
        """The temporary file to write in place of ``target`` (created, empty)."""
        target = Path(target)
        key = target.resolve()
        if key in {t.resolve() for t in self._pending}:
            raise ValueError(f"{target} is already an output of this set")
        self._refuse_existing(target)
        target.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_partials(target)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.stem}.partial-{os.getpid()}-", suffix=target.suffix, dir=target.parent
        )
        os.close(fd)
        self._pending[target] = Path(tmp)
        return Path(tmp)

    def _refuse_existing(self, target: Path) -> None:
        if target.exists() and not self.overwrite:
            raise FileExistsError(f"{target} exists; pass overwrite=True (CLI: --force) to replace it")

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        try:
            if kind is None:
                with deferred_signals():
                    self._commit()
        finally:
            self._discard()

    def _discard(self) -> None:
        for tmp in self._pending.values():
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        self._pending.clear()

    def _commit(self) -> None:
        mode = _file_mode()
        for target, tmp in self._pending.items():
            self._refuse_existing(target)  # one may have appeared while we wrote
            if not tmp.exists():
                raise FileNotFoundError(f"the temporary file for {target} was never written ({tmp})")
            os.chmod(tmp, mode)  # mkstemp makes 0600; a written file gets the usual mode
        replaced: list[Path] = []
        backups: dict[Path, Path] = {}
        try:
            for target, tmp in self._pending.items():
                if target.exists():
                    fd, backup = tempfile.mkstemp(
                        prefix=f".{target.stem}.old-{os.getpid()}-", suffix=target.suffix, dir=target.parent
                    )
                    os.close(fd)
                    os.replace(target, backup)
                    backups[target] = Path(backup)
                os.replace(tmp, target)
                replaced.append(target)
        except BaseException:
            for target in replaced:
                with contextlib.suppress(FileNotFoundError):
                    target.unlink()
            for target, saved in backups.items():
                try:
                    os.replace(saved, target)
                except OSError as exc:  # the old contents stay in the backup, never deleted
                    log.error("could not put %s back from %s: %s", target, saved, exc)
            raise
        for saved in backups.values():
            with contextlib.suppress(FileNotFoundError):
                saved.unlink()
