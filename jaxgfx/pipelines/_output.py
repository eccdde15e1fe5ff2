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

:class:`StagedFiles` handles jobs whose outputs are files (``render``, ``filter``);
:class:`StagedDir` handles jobs whose output is a folder (``calibrate``).
"""

from __future__ import annotations

import os
import shutil
import tempfile

__all__ = ["StagedFiles", "StagedDir", "check_output_extension", "OutputExistsError"]

# format families by extension, and how many channels each can hold (None: any 1..4)
HDR_EXTENSIONS = (".exr", ".hdr", ".pic", ".rgbe")
LDR_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
WRITABLE_EXTENSIONS = HDR_EXTENSIONS + LDR_EXTENSIONS


class OutputExistsError(FileExistsError):
    """The target holds results and ``overwrite`` was not given."""


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
        self._created: list[str] = []

    def __enter__(self):
        try:
            for name, path in self.targets.items():
                folder = os.path.dirname(os.path.abspath(path))
                self._created += _make_parents(folder, name)
                base, ext = os.path.splitext(os.path.basename(path))
                try:
                    fd, tmp = tempfile.mkstemp(
                        prefix=f".{base}.", suffix=f".partial{ext}", dir=folder
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
        try:
            mode = 0o666 & ~_umask()  # mkstemp makes 0600 files; give the usual permissions
            for name, tmp in self.staging.items():
                os.chmod(tmp, mode)
                os.replace(tmp, self.targets[name])
        except BaseException:
            self._abort()
            raise
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
        try:
            self.path = tempfile.mkdtemp(
                prefix=f".{os.path.basename(self.out)}.", suffix=".partial", dir=parent
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
        try:
            mask = _umask()
            new = set(os.listdir(self.path))
            for n in new:
                os.chmod(os.path.join(self.path, n), 0o666 & ~mask)
            if not os.path.exists(self.out):
                os.chmod(self.path, 0o777 & ~mask)  # mkdtemp makes a 0700 folder
                os.rename(self.path, self.out)
                return False
            for n in sorted(new):
                os.replace(os.path.join(self.path, n), os.path.join(self.out, n))
            for n in self.previous:
                if n not in new:
                    os.unlink(os.path.join(self.out, n))
            self.replaced = list(self.previous)
            os.rmdir(self.path)
        except BaseException:
            self._abort()
            raise
        return False
