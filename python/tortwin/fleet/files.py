"""Files through pyarrow's filesystems: a location is a local path or a URI
(``s3://``, ``gs://``, ``hdfs://``, ``file://``); files are read whole and
written whole (under a temporary name, then moved into place), tables as
Parquet."""

from __future__ import annotations

import hashlib
import os
import uuid
from pathlib import Path

import pyarrow as pa
import pyarrow.fs as pafs
import pyarrow.parquet as pq


def _is_uri(s: str) -> bool:
    return "://" in s


def _fs(location: str) -> tuple[pafs.FileSystem, str]:
    if _is_uri(location):
        return pafs.FileSystem.from_uri(location)
    return pafs.LocalFileSystem(), os.path.abspath(location)


def _join(root: str, *parts: str) -> str:
    return "/".join([root.rstrip("/"), *parts])


def _read_bytes(location: str) -> bytes:
    fs, path = _fs(location)
    with fs.open_input_stream(path) as f:
        return f.readall()


def _exists(location: str) -> bool:
    fs, path = _fs(location)
    return fs.get_file_info(path).type == pafs.FileType.File


def _write_bytes(location: str, data: bytes) -> None:
    """Writes a file whole: under a temporary name, then moved into place."""
    fs, path = _fs(location)
    fs.create_dir(path.rsplit("/", 1)[0], recursive=True)
    partial = f"{path}.partial-{uuid.uuid4().hex}"
    with fs.open_output_stream(partial) as f:
        f.write(data)
    fs.move(partial, path)


def _put_file(local: Path, location: str) -> None:
    _write_bytes(location, local.read_bytes())


def _write_parquet(location: str, table: pa.Table) -> None:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    _write_bytes(location, sink.getvalue().to_pybytes())


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()
