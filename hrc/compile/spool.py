"""The compile's low-level file writing: spools of plan texts, a worker's own files, and small helpers.

A large compile writes gigabytes of ``compiled.json`` lines and GraphML. Each plan's texts go to a spool
file as they come (`Spooled`: where each went, by spool, offset and length) or, from a worker process on
this machine, to that worker's own spools and ``stnu/`` (`WorkerFiles`); `hrc.compile.sink.PlanSink`
copies them into the final files in rank order at the end (in the kernel where it can: `kernel_copy`).
"""

from __future__ import annotations

import os
import shutil
import struct
import zipfile
import zlib
from array import array
from collections.abc import Sequence
from pathlib import Path
from typing import IO

from hrc.compile.compiler import CompiledPlan
from hrc.errors import HrcError

__all__ = ["ARCHIVE_LEVEL", "DEFLATED_HEAD", "SPOOLED", "Spooled", "WorkerFiles", "Written", "deflated", "kernel_copy",
           "link_or_copy", "open_folder", "needs_zip64", "write_all", "write_at", "write_deflated_zip",
           "write_stnu_file"]

Written = tuple[str, int, int]  # what a worker wrote itself: a spool file's name, the offset and the length

SPOOLED = ("spool", "deflate")
"""The `PlanSink.stnu_to` values whose GraphML goes to spools: as text (``spool``: the files of the plans
kept, with ``--best``), or deflated for ``stnu.zip`` (``deflate``: `deflated`, where the plan was compiled)."""

ARCHIVE_LEVEL = 1
"""The deflate level of ``stnu.zip`` (`hrc.compile.sink.PlanSink._write_archive` says why 1)."""

DEFLATED_HEAD = struct.Struct("<II")  # a deflated spool entry's head: its text's CRC-32 and size
_CENTRAL = struct.Struct("<4s4B4HL2L5H2L")  # a zip's central directory entry (`zipfile.structCentralDir`)
_END = struct.Struct("<4s4H2LH")  # its end record (`zipfile.structEndArchive`)


def deflated(raw: bytes) -> bytes:
    """`raw` as a ``deflate`` spool holds it: its CRC-32 and size (`DEFLATED_HEAD`), then its bytes deflated
    exactly as `zipfile` deflates a file written whole at level `ARCHIVE_LEVEL` (raw deflate, one
    ``compress`` call and a ``flush``), so that `write_deflated_zip` writes the archive `zipfile` writes.
    Done in the workers, as the plans are compiled (issue 38: deflating kitting_7picks' 1.25 GB of GraphML
    was about 6 s at the end of its compile, with a core idle, and the spools held the whole of it)."""
    compressor = zlib.compressobj(ARCHIVE_LEVEL, zlib.DEFLATED, -15)
    return DEFLATED_HEAD.pack(zlib.crc32(raw), len(raw)) + compressor.compress(raw) + compressor.flush()


def write_deflated_zip(out: IO[bytes], names: Sequence[str], places: Sequence[tuple[int, int, int]]) -> None:
    """A zip archive of files `names` (in order), entry k's data a `deflated` spool entry at ``places[k]``
    (a readable descriptor, the offset, the size), with the bytes `zipfile.ZipFile.writestr` writes for
    each as a `ZipInfo` dated 1980-01-01, mode 0644, deflated at `ARCHIVE_LEVEL` (tested): each local
    header (`ZipInfo.FileHeader`), the deflated data as it is (copied in the kernel where it can be), then
    the central directory and its end record as `zipfile` lays them out. No ZIP64: an archive that needs
    it (more than 65,535 files, or 2 GB) is the caller's to write with `zipfile` (`needs_zip64`)."""
    central = []
    copy = hasattr(os, "copy_file_range")
    for name, (fd, at, size) in zip(names, places, strict=True):
        info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        info.flag_bits = 0
        info.CRC, info.file_size = DEFLATED_HEAD.unpack(os.pread(fd, DEFLATED_HEAD.size, at))
        info.compress_size = size - DEFLATED_HEAD.size
        info.header_offset = out.tell()
        out.write(info.FileHeader(False))
        if copy:
            out.flush()
            copy = kernel_copy(fd, out.fileno(), info.compress_size, at + DEFLATED_HEAD.size)
            out.seek(0, os.SEEK_END)
        if not copy:
            out.write(os.pread(fd, info.compress_size, at + DEFLATED_HEAD.size))
        central.append(info)
    start = out.tell()
    for info in central:
        filename = info.filename.encode("ascii")
        out.write(_CENTRAL.pack(b"PK\x01\x02", info.create_version,
                              info.create_system, info.extract_version, info.reserved, info.flag_bits,
                              info.compress_type, 0, (1 << 5) | 1, info.CRC, info.compress_size, info.file_size,
                              len(filename), 0, 0, 0, info.internal_attr, info.external_attr, info.header_offset))
        out.write(filename)
    end = out.tell()
    out.write(_END.pack(b"PK\x05\x06", 0, 0, len(central), len(central), end - start, start, 0))


def needs_zip64(names: Sequence[str], sizes: Sequence[int]) -> bool:
    """Whether `zipfile` would write an archive of these files (their deflated spool entries' sizes) with
    ZIP64 records (`write_deflated_zip` writes none): more than 65,535 files, or offsets past 2 GB."""
    total = sum(sizes) + sum(76 + 2 * len(n) for n in names) + 22  # headers: 30 + 46 + the name twice
    return len(names) > zipfile.ZIP_FILECOUNT_LIMIT or total > zipfile.ZIP64_LIMIT


class WorkerFiles:
    """A worker's own files in the output folder (`compact_records` with a folder): its spool of line
    tails ``.plans.PID.spool`` and, by `PlanSink.stnu_to`, the GraphML files in ``stnu/`` or its spool
    ``.stnu.PID.spool`` (for the archive, or for the files of the plans kept in the end); opened at the
    worker's first unit of work, appended to with one write per unit. The parent reads the spools when
    it writes ``compiled.json`` and ``stnu.zip`` and removes them (`PlanSink`); after an interrupt, it
    removes the GraphML files of plans it never heard of."""

    _open: dict[str, WorkerFiles] = {}  # per process (a forked child opens its own): folder -> files

    def __init__(self, folder: str, stnu_to: str) -> None:
        self.pid, self.stnu_to = os.getpid(), stnu_to
        self.names = (f".plans.{self.pid}.spool", f".stnu.{self.pid}.spool")
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND
        self.fds = [os.open(os.path.join(folder, self.names[0]), flags, 0o666),
                    os.open(os.path.join(folder, self.names[1]), flags, 0o666) if stnu_to in SPOOLED else -1]
        self.at = [os.fstat(fd).st_size if fd >= 0 else 0 for fd in self.fds]
        self.stnu_path = os.path.join(folder, "stnu")
        self.stnu_dir = open_folder(self.stnu_path) if stnu_to == "files" else None

    @classmethod
    def of(cls, folder: str, stnu_to: str) -> WorkerFiles:
        files = cls._open.get(folder)
        if files is None or files.pid != os.getpid() or files.stnu_to != stnu_to:
            for old in cls._open.values():  # another run's, in a process that lives on (a test's)
                old.close()
            cls._open = {folder: cls(folder, stnu_to)}
            files = cls._open[folder]
        return files

    def close(self) -> None:
        if self.pid == os.getpid():
            for fd in (*self.fds, self.stnu_dir):
                if fd is not None and fd >= 0:
                    os.close(fd)

    def _append(self, which: int, texts: list[bytes], newline: bool) -> list[Written]:
        """Append `texts` to spool `which` in one write; where each went."""
        out: list[Written] = []
        data = bytearray()
        at = self.at[which]
        for raw in texts:
            out.append((self.names[which], at + len(data), len(raw)))
            data += raw
            if newline:
                data += b"\n"
        write_all(self.fds[which], data)
        self.at[which] = at + len(data)
        return out

    def lines(self, tails: list[str]) -> list[Written]:
        return self._append(0, [tail.encode("utf-8") for tail in tails], newline=True)

    def stnus(self, compiled: list[CompiledPlan], texts: list[str]) -> list[str | Written | None]:
        """Write each plan's GraphML `texts` where `stnu_to` says (``deflate``: `deflated`); where each went."""
        if self.stnu_to == "files":
            for cp, text in zip(compiled, texts, strict=True):
                write_stnu_file(self.stnu_dir, self.stnu_path, cp.plan.id, text)
            return [None] * len(compiled)
        if self.stnu_to == "spool":
            return list(self._append(1, [text.encode("utf-8") for text in texts], newline=False))
        if self.stnu_to == "deflate":
            return list(self._append(1, [deflated(text.encode("utf-8")) for text in texts], newline=False))
        return [None] * len(compiled)



class Spooled:
    """Where a text of each plan went, in the order the plans came: a spool (by number; 0 is this
    process's own, written through `add_text`; the others are workers', `WorkerFiles`), an offset and a
    length. Each text is followed by `sep` in its spool."""

    def __init__(self, folder: Path, own: str, sep: bytes) -> None:
        self.folder, self.sep = folder, sep
        self.names = [own]
        self._numbers = {own: 0}
        self.own: IO[bytes] = open(folder / own, "w+b")  # noqa: SIM115 - closed in close
        self.file, self.at, self.size = array("H"), array("q"), array("q")
        self._fds: list[int] = []

    def __len__(self) -> int:
        return len(self.at)

    def add_text(self, data: bytes) -> None:
        self.file.append(0)
        self.at.append(self.own.tell())
        self.size.append(len(data))
        self.own.write(data + self.sep)

    def add_written(self, written: Written) -> None:
        name, at, size = written
        number = self._numbers.get(name)
        if number is None:
            if os.path.basename(name) != name or not name.startswith("."):  # pragma: no cover - ours alone
                raise HrcError(f"internal: a worker wrote to {name!r}, not a spool of the output folder")
            number = self._numbers[name] = len(self.names)
            self.names.append(name)
        self.file.append(number)
        self.at.append(at)
        self.size.append(size)

    def fds(self) -> list[int]:
        """A readable descriptor per spool (the own one flushed), opened once."""
        self.own.flush()
        if not self._fds:
            self._fds = [self.own.fileno()] + [os.open(self.folder / n, os.O_RDONLY) for n in self.names[1:]]
        return self._fds

    def read(self, i: int) -> bytes:
        return os.pread(self.fds()[self.file[i]], self.size[i], self.at[i])

    def close(self) -> None:
        for fd in self._fds[1:]:
            os.close(fd)
        self._fds = []
        self.own.close()



def link_or_copy(source: Path, target: Path) -> None:
    """`target` as a hard link to `source` (the same bytes, no copy), or a copy where links fail."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def open_folder(path: str) -> int | None:
    """`path` opened as a folder, for files opened relative to it (no path to build and resolve per
    plan: 40,320 of them); None where the system has no ``dir_fd``."""
    if os.open not in os.supports_dir_fd:
        return None
    return os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))


def write_stnu_file(folder: int | None, path: str, plan_id: str, text: str | bytes) -> None:
    """A plan's GraphML file ``PLAN.graphml`` in ``stnu/`` (open as `folder`, or at `path`)."""
    name = f"{plan_id}.graphml"
    write_at(folder, name if folder is not None else os.path.join(path, name),
              text.encode("utf-8") if isinstance(text, str) else text)


def write_at(folder: int | None, name: str, data: bytes) -> None:
    """Write file `name` (new or emptied, as ``open(name, "wb")`` does) in the open folder `folder` (a file
    descriptor; None: `name` is a path)."""
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666, dir_fd=folder)
    try:
        write_all(fd, data)
    finally:
        os.close(fd)


def write_all(fd: int, data: bytes | bytearray) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def kernel_copy(src: int, dst: int, size: int, offset: int) -> bool:
    """Append `size` bytes of file `src` from `offset` to file `dst` (at its end) without reading them
    into this process (``copy_file_range``: the end of a kitting_7picks run, 687 MB of lines, went from
    3.4 to 1.6 s); False, with nothing written, where the kernel cannot (another file system on an older
    kernel, or a file system without it)."""
    done = 0
    while done < size:
        try:
            n = os.copy_file_range(src, dst, size - done, offset + done)
        except OSError:
            if done:  # pragma: no cover - failing midway: no known case
                raise
            return False
        if n == 0:  # pragma: no cover - the spool ends early: cannot happen while we hold it
            raise HrcError("internal: the plans' spool ended before its last line")
        done += n
    return True

