"""Run folders written whole or not at all: the one rule every command's ``--out`` follows.

:func:`run_folder` hands a command a fresh temporary folder beside ``--out``
(``.NAME.partial-XXXX``); when the command returns, the folder is moved into place in one rename
(the earlier run, if any, is removed after). If the command fails or is interrupted (Ctrl-C,
SIGINT), the temporary folder is deleted and ``--out`` is left exactly as it was: an earlier
run's files stay whole and no stale file of it survives beside new ones, and a folder that did
not exist is not created. :func:`atomic_file` does the same for a single output file.

A non-empty ``--out`` is replaced only with ``overwrite=True`` (``--overwrite``), and only if an
earlier run wrote it (its :data:`MARKER` file): a folder of the user's own files is never
replaced.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

MARKER = ".uav-formation-run.json"  # written last into every run folder: what wrote it, when


def check_out(out: str | Path, overwrite: bool = False, option: str = "--out") -> Path:
    """``out`` as a path a run may be moved to, else a one-line ``ValueError`` naming ``option``.

    Refused: a file; the current folder or one holding it; a non-empty folder without
    ``overwrite``; with ``overwrite``, a non-empty folder that no run wrote.
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise ValueError(
            f"{option} {str(out)!r} is a file; expected a directory (it will be created)"
        )
    here, target = Path.cwd().resolve(), path.resolve()
    if target == here or target in here.parents:
        raise ValueError(
            f"{option} {str(out)!r} is the current folder or holds it; name a folder for the run"
        )
    if path.is_dir() and any(path.iterdir()):
        if not overwrite:
            raise ValueError(
                f"{option} {str(out)!r} is not empty (an earlier run?); pass --overwrite to "
                "replace it, or choose another folder"
            )
        if not (path / MARKER).is_file():
            raise ValueError(
                f"{option} {str(out)!r} holds files that no uav-formation run wrote (no {MARKER}); "
                "--overwrite replaces only run folders: choose an empty or new folder"
            )
    return path


@contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT ignored for the few system calls of a swap (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _swap(new: Path, out: Path) -> None:
    """Move ``new`` to ``out``; an existing ``out`` is renamed aside first, then removed."""
    with _signals_held():
        old = None
        if out.exists():
            old = out.with_name(f".{out.name}.old-{uuid.uuid4().hex[:8]}")
            os.rename(out, old)
        try:
            os.rename(new, out)
        except OSError:
            if old is not None:
                os.rename(old, out)
            raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _missing_parents(path: Path) -> list[Path]:
    """The folders of ``path`` (itself included) that do not exist yet, deepest first."""
    missing = []
    while not path.exists():
        missing.append(path)
        if path.parent == path:
            break
        path = path.parent
    return missing


def _note(error: BaseException, text: str) -> None:
    if hasattr(error, "add_note"):
        error.add_note(text)


@contextmanager
def run_folder(
    out: str | Path, *, overwrite: bool = False, command: str = "", option: str = "--out"
) -> Iterator[Path]:
    """A temporary folder to write a run into, moved onto ``out`` when the block ends normally.

    Args:
        out: the run's folder (``--out``); checked by :func:`check_out` before anything runs.
        overwrite: replace an earlier run's folder.
        command: what wrote the run, recorded in :data:`MARKER`.
        option: the option's name in error messages.

    On an exception or an interrupt the temporary folder is removed, ``out`` is untouched, and
    a note saying so is added to the exception (the CLI prints it).
    """
    path = check_out(out, overwrite, option)
    created = _missing_parents(path.parent)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-", dir=path.parent))
    os.chmod(partial, 0o777 & ~_umask())  # mkdtemp's 0o700 would become the run folder's mode
    try:
        yield partial
        record = {
            "command": command,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        (partial / MARKER).write_text(json.dumps(record) + "\n", encoding="utf-8")
        _swap(partial, path)
    except BaseException as error:
        shutil.rmtree(partial, ignore_errors=True)
        for folder in created:  # deepest first; stop at one that is no longer empty
            try:
                folder.rmdir()
            except OSError:
                break
        earlier = "the earlier results are left whole" if path.exists() else "nothing written"
        _note(error, f"{option} {str(out)}: {earlier}")
        raise


@contextmanager
def atomic_file(
    out: str | Path, *, overwrite: bool = False, option: str = "--out"
) -> Iterator[Path]:
    """A temporary file name beside ``out`` (same suffix), renamed onto ``out`` when the block
    ends normally and removed otherwise. An existing ``out`` needs ``overwrite``."""
    path = Path(out)
    if path.is_dir():
        raise ValueError(f"{option} {str(out)!r} is a directory; expected a file name")
    if path.exists() and not overwrite:
        raise ValueError(f"{option} {str(out)!r} exists; pass --overwrite to replace it")
    created = _missing_parents(path.parent)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial-{uuid.uuid4().hex[:8]}{path.suffix}")
    try:
        yield partial
        with _signals_held():
            os.replace(partial, path)
    except BaseException as error:
        partial.unlink(missing_ok=True)
        for folder in created:
            try:
                folder.rmdir()
            except OSError:
                break
        _note(error, f"{option} {str(out)}: left as it was")
        raise
