"""The bytes of a glTF file as downloaded: a .gltf (JSON) or a .glb (binary container), and the data it refers to.

A .glb is a 12-byte header (``glTF``, version 2, total length), a JSON chunk and an optional BIN chunk; the buffer
without a ``uri`` is that BIN chunk. Buffers and images may also be embedded as base64 ``data:`` URIs or be files
next to the .gltf. Each problem (a truncated container, a chunk of the wrong type, bad base64) is one
DiviewerError naming the file and the field.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from pathlib import Path

from diviewer.errors import DiviewerError

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942


def _glb(blob: bytes, file: Path, path, field: str) -> tuple[object, bytes | None]:
    """The JSON document and BIN chunk of a .glb container, every length checked against the file's size."""
    def bad(msg: str) -> DiviewerError:
        return DiviewerError(f"{file} is not a valid .glb: {msg}", path=path, field=field)

    if len(blob) < 12:
        raise bad(f"the file has {len(blob)} bytes, less than the 12-byte header (truncated)")
    _, version, length = struct.unpack_from("<4sII", blob, 0)
    if version != 2:
        raise bad(f"container version {version}; only glTF 2.0 (version 2) is read")
    if length > len(blob):
        raise bad(f"the header says {length} bytes, the file has {len(blob)} (truncated: download it again)")
    chunks: list[tuple[int, bytes]] = []
    at = 12
    while at < length:
        if at + 8 > length:
            raise bad(f"a chunk header at byte {at} reaches past the end ({length} bytes): truncated")
        size, kind = struct.unpack_from("<II", blob, at)
        if at + 8 + size > length:
            raise bad(f"chunk {len(chunks)} ({size} bytes at byte {at + 8}) reaches past the end ({length} bytes): "
                      f"truncated")
        chunks.append((kind, blob[at + 8:at + 8 + size]))
        at += 8 + size + (-size % 4)  # chunks are 4-byte aligned
    if not chunks or chunks[0][0] != CHUNK_JSON:
        raise bad("the first chunk is not the JSON chunk")
    try:
        doc = json.loads(chunks[0][1].decode("utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise bad(f"its JSON chunk does not parse: {type(exc).__name__}: {str(exc)[:200]}") from exc
    bins = [data for kind, data in chunks[1:] if kind == CHUNK_BIN]
    return doc, (bins[0] if bins else None)


def read_document(file: Path, *, path=None, field: str = "gltf.file") -> tuple[object, bytes | None]:
    """A glTF file's JSON document and, for a .glb, its BIN chunk (None for a .gltf), by the file's content
    (a .glb renamed .gltf is still read as a .glb)."""
    blob = file.read_bytes()
    if blob[:4] == GLB_MAGIC:
        return _glb(blob, file, path, field)
    try:
        return json.loads(blob.decode("utf-8")), None
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise DiviewerError(f"{file} is neither a glTF JSON file (.gltf) nor a binary glTF (.glb, which starts with "
                            f"'glTF'): {type(exc).__name__}: {str(exc)[:200]}", path=path, field=field) from exc


def data_uri(uri: str, doc, field: str, what: str) -> bytes:
    """The bytes of a base64 ``data:`` URI (``data:application/octet-stream;base64,...``)."""
    head, sep, payload = uri.partition(",")
    if not sep or not head.endswith(";base64"):
        raise doc.err(field, f"an embedded {what} must be a base64 data URI (data:<type>;base64,<data>)")
    try:
        return base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise doc.err(field, f"the embedded {what}'s base64 data is malformed: {exc}") from exc


def view_bytes(doc, buffers: list[bytes], index, field: str) -> bytes:
    """The bytes of buffer view ``index`` (referred to by ``field``), its range checked against its buffer."""
    view = doc.get("bufferViews", index, field)
    vf = f"bufferViews[{index}]"
    buf = buffers[doc.index("buffers", view.get("buffer"), f"{vf}.buffer")]
    off, length = doc.int(view, "byteOffset", f"{vf}.byteOffset", 0), doc.int(view, "byteLength", f"{vf}.byteLength")
    if off + length > len(buf):
        raise doc.err(vf, f"the buffer view reaches past its buffer ({off} + {length} > {len(buf)} bytes)")
    return buf[off:off + length]
