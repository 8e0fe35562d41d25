"""Every file weather-gym writes goes through here; every path read from a file is confined here.

**Safe writes.** An output is written to a fresh temporary file in the target's folder, created
with ``O_EXCL`` under an unpredictable name (``tempfile.mkstemp``: a symlink planted there cannot
redirect the write), flushed and fsynced, then moved over the target in one step (``os.replace``;
``os.link`` when the target must not exist, which refuses atomically if it appeared meanwhile).
A reader, or a run killed half-way, sees the old file or the new one, never half of one; a failed
write leaves no temporary file behind.

**One overwrite policy.** An existing output is never replaced unless the caller says so
(``overwrite=True``, on the command line ``--overwrite``): otherwise :class:`OutputExistsError`.
:func:`check_output` applies the same checks before any work starts, so a long command fails
in its first second, not after an hour.

**An input is never an output.** A command declares the files and folders it reads
(:func:`declare_inputs`); every check and every write here then refuses an output that is, or lies
inside, one of them (:class:`OutputPathError`), ``--overwrite`` or not.

**One writer at a time.** :func:`exclusive` holds an advisory lock on an output folder or file while
a long run writes it; a second run is refused up front (:class:`OutputExistsError`).

**Confinement.** :func:`resolve_inside` resolves a path read from a dataset, model file or
scenario against its root folder and refuses absolute paths, ``..`` and symlinks that lead out of
it (:class:`OutsideRootError`).

Example:
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> atomic_write_json(d / "out.json", {"k": 0.5}).read_text()
    '{"k": 0.5}'
    >>> atomic_write_json(d / "out.json", {"k": 0.6})
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.OutputExistsError: output ... already exists; pass --overwrite to replace it
    >>> resolve_inside(d, "../etc/passwd", what="annotations.json image 3")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.OutsideRootError: annotations.json image 3: '../etc/passwd' leads outside ...
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np

try:
    import fcntl
except ModuleNotFoundError:  # pragma: no cover - Windows: no advisory locks
    fcntl = None  # type: ignore[assignment]  # no such module on Windows; users check for None

from weather_gym.core._inputs import check_not_input, declare_inputs, resolve_inside
from weather_gym.core._lock import exclusive_folder
from weather_gym.core.errors import InputError, OutputExistsError, OutputPathError

__all__ = [
    "atomic_file",
    "atomic_path",
    "atomic_write",
    "atomic_write_json",
    "check_not_input",
    "check_output",
    "declare_inputs",
    "derived_outputs_replaceable",
    "exclusive",
    "exists_message",
    "open_append",
    "resolve_inside",
    "write_failure",
    "write_image",
]


# ------------------------------------------------------------------------------------ one writer
def _lock_fd(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


@contextlib.contextmanager
def exclusive(path: str | os.PathLike, *, message: str | None = None) -> Iterator[None]:
    """Hold an exclusive advisory lock on the output ``path`` while a long run writes it.

    A folder that exists is locked itself (``weather_gym.core._lock.exclusive_folder``); a file
    output is locked through ``.NAME.lock`` beside it, removed again on release. A second run asking
    for the same lock meanwhile gets :class:`OutputExistsError` (``message``, or a default naming
    ``path``) at once. No lock on systems without ``fcntl``.

    Example:
        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> with exclusive(d):
        ...     with exclusive(d / "model.onnx"):
        ...         pass
    """
    if fcntl is None:  # pragma: no cover - Windows: no lock
        yield
        return
    p = Path(path)
    text = message or (f"another weather-gym run is writing {p}; wait for it to finish or choose another output")
    if p.is_dir():
        with exclusive_folder(p, busy=text):
            yield
        return
    _make_parent(p)
    lock = p.parent / f".{p.name}.lock"
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    while True:
        try:
            fd = os.open(lock, flags, 0o644)
        except OSError as exc:
            raise OutputPathError(f"cannot lock {p} ({lock}): {exc.strerror or exc}") from None
        if not _lock_fd(fd):
            os.close(fd)
            raise OutputExistsError(text)
        try:  # the holder before us may have removed the file after we opened it: lock the current one
            if os.path.samestat(os.fstat(fd), os.stat(lock, follow_symlinks=False)):
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)


# ------------------------------------------------------------------------------ overwrite policy
def exists_message(path: str | os.PathLike, what: str = "output") -> str:
    """The one message for an output that exists (used by every command and API)."""
    return f"{what} {path} already exists; pass --overwrite to replace it"


def check_output(path: str | os.PathLike, *, overwrite: bool = False, suffixes: Sequence[str] = (),
                 what: str = "output") -> Path:
    """Check an output path before any work: the suffix, nothing in the way, no overwrite unless asked.

    Raises :class:`OutputExistsError` for an existing file without ``overwrite``, and
    :class:`OutputPathError` for a declared input (:func:`declare_inputs`), a folder where the file
    should go, a file where a folder should be, or a folder that cannot be written. Creates nothing.
    """
    p = Path(path)
    if suffixes and p.suffix.lower() not in tuple(s.lower() for s in suffixes):
        raise OutputPathError(f"{what} {p}: expected a file ending in {' or '.join(suffixes)}")
    check_not_input(p, what=what)
    if p.is_dir():
        raise OutputPathError(f"{what} {p} is a folder; give a file path")
    if p.exists() or p.is_symlink():
        if not overwrite:
            raise OutputExistsError(exists_message(p, what))
        if not p.is_file():
            raise OutputPathError(f"{what} {p} exists and is not a regular file")
    _check_folder(p.parent, what=f"{what} {p}")
    return p


def derived_outputs_replaceable(owner: str | os.PathLike, outputs: Sequence[str | os.PathLike], *,
                                overwrite: bool = False) -> bool:
    """May a resumable run replace ``outputs``, the files it regenerates from its results file ``owner``?

    Yes with ``overwrite``, or when ``owner`` already exists (the folder holds this kind of run, and
    its report and plots are rewritten as the run resumes). Otherwise an existing output is someone
    else's file: :class:`OutputExistsError` before anything runs. Returns the ``overwrite`` flag to
    give the writers.
    """
    if overwrite or Path(owner).is_file():
        for p in outputs:
            check_not_input(p)
            if Path(p).is_dir():
                raise OutputPathError(f"output {p} is a folder; move it away (it would be replaced by a file)")
        return True
    for p in outputs:
        check_output(p, what=f"output (no {Path(owner).name} here, so this is not a resumed run)")
    return False


def _check_folder(folder: Path, *, what: str) -> None:
    """The nearest existing ancestor of ``folder`` must be a writable folder (missing ones are made later)."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise OutputPathError(f"{what}: {probe} is a file, not a folder")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        raise OutputPathError(f"{what}: folder {probe} is not writable")


# ----------------------------------------------------------------------------------------- writing
_UMASK: int | None = None


def _umask() -> int:
    global _UMASK
    if _UMASK is None:
        _UMASK = os.umask(0o022)
        os.umask(_UMASK)
    return _UMASK


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputPathError(f"cannot write {path}: a file stands where its folder {path.parent} should be") from None
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from None


def _mode_for(path: Path) -> int:
    """The permissions of the file being replaced, else the usual ``0666 & ~umask``."""
    with contextlib.suppress(OSError):
        st = os.stat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    return 0o666 & ~_umask()


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _commit(tmp: Path, path: Path, overwrite: bool) -> None:
    """Move the finished temporary file ``tmp`` to ``path`` (atomic no-clobber unless ``overwrite``)."""
    if overwrite:
        if path.is_dir():
            raise OutputPathError(f"cannot write {path}: it is a folder")
        os.replace(tmp, path)
    else:
        try:
            os.link(tmp, path)  # fails with EEXIST if the target appeared meanwhile: nothing is clobbered
        except FileExistsError:
            raise OutputExistsError(exists_message(path)) from None
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
                raise
            if path.exists() or path.is_symlink():  # no hard links here: check, then rename
                raise OutputExistsError(exists_message(path)) from None
            os.replace(tmp, path)
        else:
            os.unlink(tmp)
    _fsync_dir(path.parent)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """A fresh temporary file path beside ``path`` (same suffix) for writers that need a file name
    (``cv2.VideoWriter``, ``torch.onnx.export``); on a clean exit it is fsynced and moved to ``path``.

    The temporary file exists (empty, created with ``O_EXCL``) when the block starts; on an
    exception it is removed and ``path`` is untouched.

    Example:
        >>> import tempfile, pathlib
        >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
        >>> with atomic_path(p) as tmp:
        ...     _ = tmp.write_text("hello")
        >>> p.read_text()
        'hello'
    """
    path = Path(path)
    check_not_input(path)
    if path.is_dir():
        raise OutputPathError(f"cannot write {path}: it is a folder")
    if not overwrite and (path.exists() or path.is_symlink()):
        raise OutputExistsError(exists_message(path))
    _make_parent(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    except OSError as exc:
        raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from None
    tmp = Path(name)
    try:
        os.fchmod(fd, _mode_for(path))
        os.close(fd)
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        _commit(tmp, path, overwrite)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputExistsError | OutputPathError) \
                and exc.errno in _ENVIRONMENT_ERRNOS:
            raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from None
        raise


_ENVIRONMENT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG})
"""Write failures that are the machine's state, not a bug: reported as ``OutputPathError``."""


def write_failure(path: str | os.PathLike, exc: BaseException) -> BaseException:
    """The error to raise for ``exc``, a failed write to ``path``: an :class:`OutputPathError` naming
    ``path`` when it is the machine's state (disk full, quota, read-only, no permission, file too
    large), else ``exc`` itself (a bug keeps its traceback). For writers that cannot go through
    :func:`atomic_path` alone (a journal's rows, a video encoder).

    Example:
        >>> import errno
        >>> write_failure("out.mp4", OSError(errno.ENOSPC, "No space left on device"))
        OutputPathError('cannot write out.mp4: No space left on device')
    """
    if isinstance(exc, OSError) and not isinstance(exc, OutputPathError | OutputExistsError) \
            and exc.errno in _ENVIRONMENT_ERRNOS:
        return OutputPathError(f"cannot write {path}: {exc.strerror or exc}")
    return exc


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, mode: str = "w", *, overwrite: bool = False,
                encoding: str | None = "utf-8", newline: str | None = None) -> Iterator[IO[Any]]:
    """An open file object on a fresh temporary file beside ``path``; moved to ``path`` on a clean exit.

    ``mode`` is ``"w"`` (text, ``encoding``) or ``"wb"``.

    Example:
        >>> import tempfile, pathlib
        >>> p = pathlib.Path(tempfile.mkdtemp()) / "rows.csv"
        >>> with atomic_file(p, newline="") as f:
        ...     _ = f.write("a,b\\n1,2\\n")
        >>> p.read_text()
        'a,b\\n1,2\\n'
    """
    if mode not in ("w", "wb"):
        raise InputError(f"atomic_file mode must be 'w' or 'wb', got {mode!r}")
    with atomic_path(path, overwrite=overwrite) as tmp:
        kwargs: dict[str, Any] = {} if "b" in mode else {"encoding": encoding, "newline": newline}
        with open(tmp, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())


def open_append(path: str | os.PathLike) -> IO[str]:
    """A journal opened for appending text (created when missing), never through a symlink.

    For the append-only files of resumable runs (a results table, a render journal), whose rows
    are flushed one by one; everything else is written whole with :func:`atomic_write`.
    """
    path = Path(path)
    check_not_input(path)
    _make_parent(path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputPathError(f"cannot append to {path}: it is a symbolic link") from None
        raise OutputPathError(f"cannot append to {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OutputPathError(f"cannot append to {path}: not a regular file")
    return os.fdopen(fd, "a", encoding="utf-8", newline="")


def atomic_write(path: str | os.PathLike, data: str | bytes, *, overwrite: bool = False,
                 check: Callable[[Path], object] | None = None) -> Path:
    """Write ``data`` (text as UTF-8, or bytes) to ``path`` safely (see the module docstring).

    ``check(tmp_path)`` may validate the written file first; if it raises, ``path`` is left as it
    was. The file gets the permissions of the file it replaces, else the usual ``0666 & ~umask``.
    """
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as f:
            f.write(data if isinstance(data, bytes) else data.encode("utf-8"))
            f.flush()
            os.fsync(f.fileno())
        if check is not None:
            check(tmp)
    return Path(path)


def atomic_write_json(path: str | os.PathLike, obj: Any, *, overwrite: bool = False, indent: int | None = None,
                      sort_keys: bool = False, default: Callable[[Any], Any] | None = None) -> Path:
    """``obj`` as JSON (a final newline when indented), written with :func:`atomic_write`."""
    text = json.dumps(obj, indent=indent, sort_keys=sort_keys, default=default)
    return atomic_write(path, text + "\n" if indent is not None else text, overwrite=overwrite)


def write_image(path: str | os.PathLike, image: Any, *, overwrite: bool = False, rgb: bool = True,
                params: Sequence[int] = ()) -> Path:
    """Encode an image by ``path``'s suffix (OpenCV) and write it with :func:`atomic_write`.

    ``image``: uint8 RGB ``(H, W, 3)`` (``rgb=False``: already BGR or single channel, e.g. a uint16
    depth map). An unknown suffix is an :class:`OutputPathError` before anything is written.

    Example:
        >>> import numpy as np, tempfile, pathlib
        >>> p = write_image(pathlib.Path(tempfile.mkdtemp()) / "a.png", np.zeros((4, 6, 3), np.uint8))
        >>> p.stat().st_size > 0
        True
    """

    p = Path(path)
    arr = np.asarray(image)
    if rgb and arr.ndim == 3 and arr.shape[2] == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGB2BGR)
    try:
        ok, buf = cv2.imencode(p.suffix or ".", arr, list(params))
    except cv2.error:
        ok, buf = False, None
    if not ok or buf is None:
        raise OutputPathError(f"cannot write image {p}: OpenCV cannot encode a {arr.dtype} {arr.shape} image "
                              f"as {p.suffix or '(no suffix)'}; use .png or .jpg")
    return atomic_write(p, buf.tobytes(), overwrite=overwrite)


def file_id(path: str | os.PathLike) -> str:
    """First 12 hex digits of the SHA-256 of a file (identifies a model or a dataset's annotations)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:12]
