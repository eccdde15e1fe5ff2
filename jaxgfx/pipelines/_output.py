"""Output safety for the jobs: check targets before computing, stage, then move into place.

The guarantees (documented in README.md, "Command line"):

* Targets are checked **before** any computation: the output format is known from the
  extension and can hold the data, no two outputs of one job are the same file, the target is
  not a directory (files) or a file (directories), and its folder is writable (a staging file
  or folder is created there up front, which proves it).
* Results are written to a staging file / folder next to the target (same file system) and
  moved into place with ``os.replace`` only when the whole job has succeeded. On failure the
  staging area is removed, the target is untouched, and folders the job created are removed.
* A target that already holds results is refused unless ``overwrite=True`` (``--overwrite``);
  with it, the new results replace the old ones, and stale outputs of the previous run (names
  of this job that the new run does not write) are removed so the folder never mixes runs.
  Each replacement is announced to the callbacks of :func:`report_replacements` (the CLI
  prints them, so every subcommand says so without code of its own).
* Staging names carry the owning process: ``.<name>.<pid>@<host>.<random>.partial[.ext]``.
  Entering a stage removes the staging entries in the same folder whose process (on this
  host) is gone: what a killed (SIGKILL) or crashed run left behind. Another live run's
  staging is never touched (its pid is alive; other hosts' entries are never removed).
* :func:`cleanup_on_signals` (used by the CLI) turns SIGTERM / SIGHUP into a
  :class:`Terminated` exception (SIGINT stays ``KeyboardInterrupt``), so the staging is removed
  as on any other failure; a signal that arrives while results are being moved into place is
  held until the move is complete, so a target never mixes two runs.

:class:`StagedFiles` handles jobs whose outputs are files (``render``, ``filter``);
:class:`StagedDir` handles jobs whose output is a folder (``calibrate``).
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import tempfile
import threading

from jaxgfx.io import WRITE_EXTENSIONS

__all__ = [
    "StagedFiles",
    "StagedDir",
    "check_output_extension",
    "OutputExistsError",
    "Terminated",
    "cleanup_on_signals",
    "report_replacements",
    "remove_stale_staging",
]

# what can be written, by extension: jaxgfx.io owns the table
WRITABLE_EXTENSIONS = WRITE_EXTENSIONS


class OutputExistsError(FileExistsError):
    """The target holds results and ``overwrite`` was not given."""


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived (raised by the handler of :func:`cleanup_on_signals`)."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)


# ----------------------------------------------------------------------------- signals

_SIGNAL_STATE = {"defer": 0, "pending": None}


def _raise_for(signum: int):
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def _on_signal(signum, frame):
    if _SIGNAL_STATE["defer"]:  # moving results into place: finish that first
        _SIGNAL_STATE["pending"] = _SIGNAL_STATE["pending"] or signum
        return
    _raise_for(signum)


@contextlib.contextmanager
def cleanup_on_signals():
    """While inside: SIGTERM and SIGHUP raise :class:`Terminated`, SIGINT ``KeyboardInterrupt``,
    so ``with StagedFiles/StagedDir`` blocks remove their staging as on any failure. Handlers
    that are not the default ones (``nohup``'s ignored SIGHUP, an embedding program's own) are
    kept; the previous handlers are restored on exit. Outside the main thread: no change."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for name in ("SIGTERM", "SIGHUP", "SIGINT"):
        sig = getattr(signal, name, None)
        if sig is None:
            continue
        old = signal.getsignal(sig)
        default = signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL
        if old is default:
            previous[sig] = old
            signal.signal(sig, _on_signal)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def _signals_held():
    """Hold the signals of :func:`cleanup_on_signals` inside (results being moved into place);
    one that arrived is raised on exit (unless the block itself raised)."""
    _SIGNAL_STATE["defer"] += 1
    try:
        yield
    finally:
        _SIGNAL_STATE["defer"] -= 1
        pending = _SIGNAL_STATE["pending"] if not _SIGNAL_STATE["defer"] else None
        if pending is not None:
            _SIGNAL_STATE["pending"] = None
    if pending is not None:
        _raise_for(pending)


# ----------------------------------------------------------------------------- replacements

_LISTENERS: list = []


@contextlib.contextmanager
def report_replacements(callback):
    """While inside, ``callback(message)`` is called each time a stage replaced previous
    results (``--overwrite``), with one line naming them."""
    _LISTENERS.append(callback)
    try:
        yield
    finally:
        _LISTENERS.remove(callback)


def _announce(message: str) -> None:
    for callback in list(_LISTENERS):
        callback(message)


# ----------------------------------------------------------------------------- staging names

_HOST = re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname())[:48] or "host"
_STAGING_RE = re.compile(
    r"^\..+\.(?P<pid>[1-9][0-9]{0,9})@(?P<host>[A-Za-z0-9-]+)\.[a-z0-9_]+\.partial"
    r"(\.[A-Za-z0-9]+)?$"
)


def _owner_tag() -> str:
    return f"{os.getpid()}@{_HOST}"


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError, ValueError):
        return True  # EPERM: another user's live process; anything else: leave it alone
    return True


def remove_stale_staging(folder) -> list[str]:
    """Remove the staging files/folders in ``folder`` left by runs on this host whose process
    is gone (killed or crashed); returns their paths. Never raises."""
    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for n in names:
        m = _STAGING_RE.match(n)
        if m is None or m["host"] != _HOST or _alive(int(m["pid"])):
            continue
        p = os.path.join(folder, n)
        try:
            if os.path.isdir(p) and not os.path.islink(p):
                shutil.rmtree(p)
            else:
                os.unlink(p)
        except OSError:
            continue
        removed.append(p)
    return removed


def check_output_extension(path, name: str, allowed=WRITABLE_EXTENSIONS) -> str:
    """Lower-case extension of ``path``; ``ValueError`` naming ``name`` unless in ``allowed``."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in allowed:
        raise ValueError(
            f"{name}: cannot write {os.fspath(path)!r}: unsupported extension {ext or '(none)'!r}; "
            f"writable: {' '.join(allowed)}"
        )
    return ext


def _named(e: OSError, name: str) -> OSError:
    """The same OS error with ``name`` (the argument) in front of its message."""
    return type(e)(e.errno, f"{name}: {e.strerror or e}", e.filename)


def _make_parents(folder: str, name: str = "output") -> list[str]:
    """``os.makedirs(folder)``; returns the folders it created (deepest last)."""
    try:
        return _make_parents_raw(folder)
    except OSError as e:
        raise _named(e, name) from None


def _make_parents_raw(folder: str) -> list[str]:
    created = []
    probe = os.path.abspath(folder)
    while not os.path.exists(probe):
        created.append(probe)
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    if os.path.exists(probe) and not os.path.isdir(probe):
        raise NotADirectoryError(20, "not a directory (a file is in the way)", probe)
    for d in reversed(created):
        os.mkdir(d)
    return list(reversed(created))


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _remove_created(created: list[str]) -> None:
    for d in reversed(created):
        try:
            os.rmdir(d)
        except OSError:
            pass


class StagedFiles:
    """Stage output files: ``{name: final path}`` → ``{name: staging path}``.

    Use as a context manager; write to ``self.staging[name]``; on a clean exit each staging
    file is moved onto its final path (``os.replace``, atomic per file). On an exception
    nothing is moved and the staging files are removed.
    """

    def __init__(self, targets: dict[str, str], *, overwrite: bool = False, what="output"):
        self.targets = {k: os.fspath(v) for k, v in targets.items()}
        self.overwrite = overwrite
        seen: dict[str, str] = {}
        for name, path in self.targets.items():
            key = os.path.normcase(os.path.realpath(path))
            if key in seen:
                raise ValueError(
                    f"{name}: {path!r} is the same file as the {seen[key]} output; "
                    "choose different names"
                )
            seen[key] = name
            if os.path.isdir(path):
                raise IsADirectoryError(21, f"{name}: is a directory, expected a file path", path)
            if os.path.lexists(path) and not overwrite:
                raise OutputExistsError(
                    17, f"{name}: already exists; pass --overwrite to replace it", path
                )
        self.staging: dict[str, str] = {}
        self.replaced: list[str] = []
        self._created: list[str] = []

    def __enter__(self):
        try:
            for name, path in self.targets.items():
                folder = os.path.dirname(os.path.abspath(path))
                self._created += _make_parents(folder, name)
                remove_stale_staging(folder)
                base, ext = os.path.splitext(os.path.basename(path))
                try:
                    fd, tmp = tempfile.mkstemp(
                        prefix=f".{base}.{_owner_tag()}.", suffix=f".partial{ext}", dir=folder
                    )
                except OSError as e:
                    raise _named(e, name) from None
                os.close(fd)
                self.staging[name] = tmp
        except BaseException:
            self._abort()
            raise
        return self

    def _abort(self):
        for tmp in self.staging.values():
            try:
                os.unlink(tmp)
            except OSError:
                pass
        _remove_created(self._created)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self._abort()
            return False
        with _signals_held():
            try:
                mode = 0o666 & ~_umask()  # mkstemp makes 0600 files; give the usual permissions
                existed = [p for p in self.targets.values() if os.path.lexists(p)]
                for name, tmp in self.staging.items():
                    os.chmod(tmp, mode)
                    os.replace(tmp, self.targets[name])
            except BaseException:
                self._abort()
                raise
            self.replaced = existed
        if existed:
            _announce(
                "replaced the previous results: " + ", ".join(os.path.abspath(p) for p in existed)
            )
        return False


class StagedDir:
    """Stage an output folder ``out`` holding files named in ``known_names``.

    ``self.path`` is a fresh staging folder next to ``out``; on a clean exit its files move
    into ``out`` (renaming the whole folder when ``out`` does not exist yet, else one
    ``os.replace`` per file, after removing stale ``known_names`` the new run did not write).
    ``self.replaced`` lists the previous results that were replaced. On an exception the
    staging folder is removed and ``out`` is untouched (not created when it did not exist).
    """

    def __init__(self, out, known_names, *, overwrite: bool = False, name: str = "--out"):
        self.out = os.path.abspath(os.fspath(out))
        self.known = tuple(known_names)
        self.name = name
        self.replaced: list[str] = []
        if os.path.exists(self.out) and not os.path.isdir(self.out):
            raise NotADirectoryError(
                20, f"{name}: is a file, expected a folder for the results", os.fspath(out)
            )
        self.previous = (
            sorted(n for n in self.known if os.path.lexists(os.path.join(self.out, n)))
            if os.path.isdir(self.out)
            else []
        )
        if self.previous and not overwrite:
            raise OutputExistsError(
                17,
                f"{name}: holds the results of a previous run ({', '.join(self.previous)}); "
                "pass --overwrite to replace them",
                os.fspath(out),
            )
        self._created: list[str] = []
        self.path = None

    def __enter__(self):
        parent = os.path.dirname(self.out)
        self._created = _make_parents(parent, self.name)
        remove_stale_staging(parent)
        try:
            self.path = tempfile.mkdtemp(
                prefix=f".{os.path.basename(self.out)}.{_owner_tag()}.",
                suffix=".partial",
                dir=parent,
            )
        except OSError as e:
            _remove_created(self._created)
            raise _named(e, self.name) from None
        except BaseException:
            _remove_created(self._created)
            raise
        return self

    def _abort(self):
        shutil.rmtree(self.path, ignore_errors=True)
        _remove_created(self._created)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self._abort()
            return False
        with _signals_held():
            try:
                self._commit()
            except BaseException:
                self._abort()
                raise
        if self.replaced:
            _announce(f"replaced the previous results in {self.out} ({', '.join(self.replaced)})")
        return False

    def _commit(self):
        mask = _umask()
        new = set(os.listdir(self.path))
        for n in new:
            os.chmod(os.path.join(self.path, n), 0o666 & ~mask)
        if not os.path.exists(self.out):
            os.chmod(self.path, 0o777 & ~mask)  # mkdtemp makes a 0700 folder
            os.rename(self.path, self.out)
            return
        for n in sorted(new):
            os.replace(os.path.join(self.path, n), os.path.join(self.out, n))
        for n in self.previous:
            if n not in new:
                os.unlink(os.path.join(self.out, n))
        self.replaced = list(self.previous)
        os.rmdir(self.path)
