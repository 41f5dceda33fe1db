"""Where a dataset lives: a local folder or any pyarrow filesystem URI (s3://, gs://, file://).

`Location` resolves a path once and reads, lists and writes files under it; `write_atomic` writes a whole
file under a hidden temporary name and renames it, so a crash never leaves a half file that looks finished.
A location is a path the user named: its file errors are raised as `PathError`s naming the file, except a write
that failed for a reason that may pass (`TransientWriteError`), which the pipeline runs again.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import uuid
from dataclasses import dataclass

from species.errors import PathError, user_path

__all__ = ["Location", "sha256_hex", "TEMP_PREFIX", "TRANSIENT_ERRNOS", "TransientWriteError"]

# Readers (pyarrow dataset discovery, our manifest) ignore names starting with '.' or '_'.
TEMP_PREFIX = ".tmp-"
# Write errors that a second try can get past (a network file system timing out, a busy device). Every other one
# (no space, no permission, a read-only file system, a path that is not a folder...) fails the same way again.
TRANSIENT_ERRNOS = frozenset({errno.EIO, errno.EAGAIN, errno.EINTR, errno.EBUSY, errno.ETIMEDOUT, errno.ESTALE,
                              errno.ECONNRESET, errno.ECONNREFUSED, errno.ECONNABORTED, errno.ENETUNREACH,
                              errno.EHOSTUNREACH})


class TransientWriteError(OSError):
    """A write that failed for a reason that may pass (errno in TRANSIENT_ERRNOS); its message names the file."""


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@dataclass(frozen=True)
class Location:
    """A dataset root: `uri` as the user gave it, the pyarrow filesystem, and the root path on it."""

    uri: str
    root: str

    @classmethod
    def resolve(cls, uri: str) -> "Location":
        if "://" not in uri:
            uri = os.path.abspath(os.path.expanduser(uri))
        return cls(uri=uri, root=_filesystem_and_path(uri)[1].rstrip("/"))

    @property
    def filesystem(self):
        # Rebuilt on use (pickling a Location to Ray workers carries only strings).
        return _filesystem_and_path(self.uri)[0]

    @property
    def is_local(self) -> bool:
        from pyarrow.fs import LocalFileSystem

        return isinstance(self.filesystem, LocalFileSystem)

    def path(self, relative: str) -> str:
        return f"{self.root}/{relative}"

    def exists(self, relative: str) -> bool:
        from pyarrow.fs import FileType

        with user_path(self.path(relative), "look up"):
            return self.filesystem.get_file_info(self.path(relative)).type == FileType.File

    def read_bytes(self, relative: str) -> bytes:
        path = self.path(relative)
        with user_path(path, "read"), self.filesystem.open_input_stream(path) as stream:
            return stream.read()

    def list(self, folder: str) -> list[str]:
        """Names of the files directly in `folder` (relative to the root), sorted; [] if it does not exist."""
        from pyarrow.fs import FileSelector, FileType

        with user_path(self.path(folder), "list"):
            infos = self.filesystem.get_file_info(FileSelector(self.path(folder), allow_not_found=True))
        return sorted(info.base_name for info in infos if info.type == FileType.File)

    def subfolders(self, folder: str = "") -> list[str]:
        """Names of the folders directly in `folder` (relative to the root), sorted; [] if it does not exist."""
        from pyarrow.fs import FileSelector, FileType

        with user_path(self.path(folder), "list"):
            infos = self.filesystem.get_file_info(FileSelector(self.path(folder), allow_not_found=True))
        return sorted(info.base_name for info in infos if info.type == FileType.Directory)

    def write_atomic(self, relative: str, data: bytes) -> None:
        """Write `data` to a temporary sibling and rename it onto `relative` (a copy + delete on object stores)."""
        fs = self.filesystem
        final = self.path(relative)
        folder, name = final.rsplit("/", 1)
        temporary = f"{folder}/{TEMP_PREFIX}{uuid.uuid4().hex}-{name}"
        try:
            fs.create_dir(folder, recursive=True)
            with fs.open_output_stream(temporary) as stream:
                stream.write(data)
            fs.move(temporary, final)
        except OSError as exc:
            # A half-written temporary would hold the space a full disk lacks; the next run's
            # remove_temporaries deletes one this cannot.
            with contextlib.suppress(OSError):
                fs.delete_file(temporary)
            if exc.errno in TRANSIENT_ERRNOS:
                raise TransientWriteError(exc.errno, f"cannot write {final}: {exc.strerror or exc}") from exc
            if exc.errno:  # the system's reason, not pyarrow's text naming our temporary file
                raise PathError(f"cannot write {final}: {os.strerror(exc.errno)}") from exc
            with user_path(final, "write"):
                raise

    def delete(self, relative: str) -> None:
        with user_path(self.path(relative), "delete"):
            self.filesystem.delete_file(self.path(relative))

    def remove_temporaries(self, folder: str) -> int:
        """Delete files a crashed writer left under temporary names; returns how many."""
        names = [n for n in self.list(folder) if n.startswith(TEMP_PREFIX)]
        for name in names:
            self.delete(f"{folder}/{name}")
        return len(names)


def _filesystem_and_path(uri: str):
    import pyarrow
    from pyarrow.fs import FileSystem

    try:
        with user_path(uri, "open"):
            return FileSystem.from_uri(uri)
    except pyarrow.ArrowInvalid as exc:
        raise PathError(f"{uri!r} is not a path or a file system URI pyarrow knows ({exc}): allowed a local path, "
                        f"file://, s3://, gs:// or hdfs://") from None
