"""Files a command writes, checked before the command does its work.

How this works: a command that reads an input (a recording, a flight log) and writes a figure or
a JSON file checks the names it will write first, so that a name it cannot write costs no work
and the input it reads is never written over. :func:`output_file` refuses a directory, a path
in no folder, and the input itself or a file inside it; :func:`different_files` two options
naming one file; :func:`output_folder` makes an output folder, or names why it cannot;
:func:`figure_file` also wants an extension matplotlib writes, or none (then ``.png`` is
added, as matplotlib adds it, so the path the command says is the path written); a ``.pgf``
figure also wants the TeX program matplotlib runs for it. :func:`write_whole` writes outputs
whole or not at all (a partial file beside each, :func:`partial_beside`, renamed into place; a
failed write, a full disk, is refused naming the option and leaves the file that was there).
:func:`folder_lock` holds an output folder for one run of a command at a time;
:func:`cache_folder` names where skeye keeps what it computes once for later runs
(``$XDG_CACHE_HOME/skeye/...``, ``~/.cache`` by default).
Each refusal is a ConfigError naming the option and the path.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from skeye.errors import ConfigError


def output_file(path: Path, option: str, source: Path | None = None,
                source_kind: str = "input") -> Path:
    """``path`` if a command may write it: not a directory, in a folder that exists, not
    ``source`` (what the command reads, its ``source_kind`` said in the refusal: "recording",
    "log") nor, when that is a folder (a EuRoC or ROS 2 log), a file in it."""
    if path.is_dir():
        raise ConfigError(f"{option} {path} is a directory: give a file name")
    folder = path.parent
    existing = folder  # the nearest part of the path that exists: a file there is named
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise ConfigError(f"{option} {path}: {existing} is not a folder")
    if not folder.is_dir():
        raise ConfigError(f"{option} {path}: no folder {folder} to write it in")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {path}: the folder {folder} is not writable")
    if source is not None and _same_file(path, source):
        raise ConfigError(f"{option} {path} is the {source_kind} {source} itself: writing it "
                          "would overwrite what is read; give another file name")
    if source is not None and source.is_dir() and _inside(path, source):
        raise ConfigError(f"{option} {path} is inside the {source_kind} {source}: writing it "
                          "could overwrite what is read; write it elsewhere")
    return path


def partial_beside(path: Path) -> tuple[Path, Path]:
    """Where a file is written whole or not at all: the file ``path`` names (a symbolic link
    followed, so it is written through and kept, as a plain write does; a link renamed over
    would be no link) and a partial file beside that, ``.NAME.PID.partial.EXT`` (the extension
    kept: matplotlib picks a figure's format by it). The caller writes the partial file, renames
    it over the target (``os.replace``) once whole, and removes it on every path: a write that
    fails part-way (a full disk) then leaves the file that was there, never one cut short."""
    target = Path(os.path.realpath(path))
    return target, target.with_name(f".{target.stem}.{os.getpid()}.partial{target.suffix}")


def write_whole(writes: list[tuple[str, Path, Callable[[Path], object]]]) -> None:
    """Each ``(option, path, write)``: written to a partial file beside ``path``, then all
    renamed into place. A write that fails (a full disk, a folder that takes no new file) is
    refused naming its option and leaves no output behind (a rename that fails removes those
    renamed before it): the --json file was left whole after the --plot failed, and a file cut
    short where the disk filled. A symbolic link is written through, as a plain write does: the
    file it names is replaced, the link kept."""
    partials: list[tuple[str, Path, Path, Path]] = []
    try:
        for option, path, write in writes:
            target, partial = partial_beside(path)
            partials.append((option, path, target, partial))
            try:
                write(partial)
            except OSError as exc:
                raise ConfigError(f"{option} {path}: cannot write it: "
                                  f"{exc.strerror or exc}") from None
        placed: list[Path] = []
        for option, path, target, partial in partials:
            try:
                os.replace(partial, target)
            except OSError as exc:  # the ones renamed already go too: neither is left
                for done in placed:
                    with contextlib.suppress(OSError):
                        done.unlink()
                raise ConfigError(f"{option} {path}: cannot write it: "
                                  f"{exc.strerror or exc}") from None
            placed.append(target)
    finally:
        for _, _, _, partial in partials:
            with contextlib.suppress(OSError):
                partial.unlink(missing_ok=True)


def output_folder(path: Path, option: str = "--out") -> Path:
    """``path`` made (with its parents) as the folder a command writes into; a file there, or
    a folder that cannot be made, is refused naming ``option``."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {path} is a file: give a folder (it is made if missing)")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{option} {path}: cannot make the folder: "
                          f"{exc.strerror or exc}") from None
    return path


def cache_folder(kind: str) -> Path:
    """Where skeye keeps ``kind`` (a camera calibration, textures) for later runs:
    ``$XDG_CACHE_HOME/skeye/KIND``, ``~/.cache/skeye/KIND`` without it (XDG's base directory
    rule). Not made here: a caller that cannot make it works without its cache.

    Raises:
        OSError: no ``XDG_CACHE_HOME`` and no home folder (``HOME`` unset and no passwd entry,
            as for a container's arbitrary user id): there is nowhere to keep anything.
    """
    base = os.environ.get("XDG_CACHE_HOME")
    if not base:
        try:
            base = str(Path.home() / ".cache")
        except RuntimeError:  # pathlib: "Could not determine home directory."
            raise OSError("no cache folder: XDG_CACHE_HOME is not set and this user has no "
                          "home folder") from None
    return Path(base) / "skeye" / kind


LOCK_NAME = ".skeye.lock"


@contextmanager
def folder_lock(folder: Path, command: str, option: str = "--out") -> Iterator[None]:
    """Hold ``folder`` (made already) while ``command`` writes into it; a second run given the
    same folder meanwhile is refused naming the process that holds it. The lock is the kernel's
    (``flock`` on ``folder/.skeye.lock``): it ends with the process however that ends.

    Raises:
        ConfigError: another process holds the folder, or the lock file cannot be made.
    """
    path = folder / LOCK_NAME
    try:
        f = open(path, "a+")  # held open until the run ends
    except OSError as exc:
        raise ConfigError(f"{option} {folder}: cannot write in the folder: "
                          f"{exc.strerror or exc}") from None
    with f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            raise ConfigError(f"{option} {folder} is in use by {holder}: wait for it to end, "
                              f"or give another {option}") from None
        f.seek(0)
        f.truncate()
        f.write(f"another {command} (pid {os.getpid()})")
        f.flush()
        yield


def different_files(first: tuple[str, Path | None], second: tuple[str, Path | None]) -> None:
    """Refuse two options naming one file (the second written would replace the first)."""
    (a_opt, a), (b_opt, b) = first, second
    if a is not None and b is not None and a.resolve() == b.resolve():
        raise ConfigError(f"{a_opt} and {b_opt} both name {a}: give each its own file")


def figure_file(path: Path, option: str, source: Path | None = None,
                source_kind: str = "input") -> Path:
    """``path`` as the figure file to write (see :func:`output_file`): its extension picks a
    format matplotlib writes (ConfigError lists them); none gives ``.png``."""
    from matplotlib.backend_bases import FigureCanvasBase

    if path.is_dir():
        raise ConfigError(f"{option} {path} is a directory: give a file name (plot.png)")
    kind = path.suffix[1:].lower()
    formats = FigureCanvasBase.get_supported_filetypes()
    if kind and kind not in formats:
        raise ConfigError(f"{option} {path}: cannot write .{kind} files; the formats are "
                          f"{', '.join('.' + f for f in sorted(formats))}")
    if kind == "pgf":  # matplotlib runs TeX to set the text: a traceback when it is missing
        import matplotlib

        tex = matplotlib.rcParams["pgf.texsystem"]
        if shutil.which(tex) is None:
            raise ConfigError(f"{option} {path}: .pgf files need {tex} (matplotlib's "
                              "pgf.texsystem), which is not installed; choose another format")
    return output_file(path if kind else path.with_name(path.name + ".png"), option, source,
                       source_kind)


def _inside(path: Path, folder: Path) -> bool:
    return path.resolve().is_relative_to(folder.resolve())


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.samefile(b)
    except OSError:  # one of them does not exist (or cannot be looked at): not the same
        return False
