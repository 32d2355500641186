"""Files through the web page: what a browser uploads (a mesh, a saved session) and what it downloads (an export,
a session). Uploaded bytes are checked (size, kind) before anything reads them, written under a name of our own in
a fresh temporary folder (the browser's file name only picks the suffix and labels messages), and the folder is
removed afterwards; a server killed mid-upload leaves its folder behind, which the next start removes.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import unicodedata
from pathlib import Path

from ...backend import io as sw_io

#: Largest file the upload fields accept (a mesh or a session).
MAX_UPLOAD_BYTES = 50_000_000  # "50 MB", as the README and the messages say
#: Mesh files the upload field takes (by the suffix of the browser's file name).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: Longest file name shown back in messages and preset titles.
MAX_SHOWN_NAME = 80
#: What a download of each export format is sent as.
MIME = {"obj": "text/plain", "ply": "application/octet-stream", "stl": "model/stl", "glb": "model/gltf-binary",
        "gltf": "model/gltf+json", "3dm": "application/octet-stream"}
#: Uploads are written to tempfile's folder as somwidget-upload-<pid>-*.
UPLOAD_PREFIX = "somwidget-upload-"


def upload_prefix() -> str:
    return f"{UPLOAD_PREFIX}{os.getpid()}-"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def sweep_uploads(own: bool = False) -> list[str]:
    """Remove upload folders left by servers that are gone (and this process's own with `own`); returns them."""
    removed = []
    root = Path(tempfile.gettempdir())
    for folder in root.glob(f"{UPLOAD_PREFIX}*"):
        pid = folder.name[len(UPLOAD_PREFIX):].split("-", 1)[0]
        mine = pid == str(os.getpid())
        if folder.is_dir() and ((own and mine) or (not mine and (not pid.isdigit() or not _pid_alive(int(pid))))):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(str(folder))
    return removed


def shown_name(raw) -> str:
    """The browser's file name made safe to show: its last path part, without control characters, at most
    MAX_SHOWN_NAME characters (keeping the suffix). Never used as a path."""
    name = str(raw or "").replace("\\", "/").rsplit("/", 1)[-1]
    name = "".join(ch for ch in name if unicodedata.category(ch)[0] != "C").strip()
    if len(name) > MAX_SHOWN_NAME:
        stem, dot, suffix = name.rpartition(".")
        if dot and stem and len(suffix) <= 8:
            name = name[:MAX_SHOWN_NAME - len(suffix) - 4] + "..." + dot + suffix
        else:
            name = name[:MAX_SHOWN_NAME - 3] + "..."
    return name or "upload"


def suffix_of(name: str) -> str:
    stem, dot, suffix = name.rpartition(".")
    return "." + suffix.lower() if dot and stem else ""


def file_of(value) -> tuple[str, bytes] | None:
    """trame's file dict (or the first of a list) -> (name to show, bytes), None for no file, or ValueError."""
    if isinstance(value, list):
        value = value[0] if value else None
    if not value:
        return None
    if not isinstance(value, dict):
        raise ValueError("upload: unexpected data from the browser")
    name = shown_name(value.get("name"))
    try:
        size = int(value.get("size") or 0)
    except (TypeError, ValueError):
        raise ValueError("upload: unexpected data from the browser") from None
    if size > MAX_UPLOAD_BYTES:
        raise ValueError(f"upload: {name!r} is {size / 1e6:.1f} MB; the limit is {MAX_UPLOAD_BYTES / 1e6:.0f} MB")
    content = value.get("content")
    if isinstance(content, list):
        content = b"".join(content)
    if isinstance(content, str):
        content = content.encode("latin-1")
    if not content:
        raise ValueError(f"upload: {name!r} is empty")
    if not isinstance(content, (bytes, bytearray, memoryview)):
        raise ValueError("upload: unexpected data from the browser")
    if len(content) > MAX_UPLOAD_BYTES:
        raise ValueError(f"upload: file is larger than {MAX_UPLOAD_BYTES / 1e6:.0f} MB")
    return name, bytes(content)


def check_mesh_name(name: str) -> str:
    """The suffix of an uploaded mesh's name; ValueError when it is not a mesh file this app reads."""
    suffix = suffix_of(name)
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"upload: {name!r} is not a mesh file this app reads; use "
                         f"{', '.join(x[1:].upper() for x in MESH_SUFFIXES)}")
    return suffix


def read_mesh(path: Path, name: str, max_vertices: int, decimate: bool = False):
    """The preset of an uploaded mesh saved as `path`, named after the browser's file `name` (io.load_mesh; with
    `decimate`, one past `max_vertices` is coarsened to it)."""
    preset = sw_io.load_mesh(path, max_vertices=max_vertices, decimate=decimate)
    suffix = suffix_of(name)
    stem = name[: -len(suffix)] if suffix else name
    preset.name = f"mesh:{stem or 'upload'}"  # never mistaken for a built-in preset of the same name
    preset.title = name
    preset.description = preset.description.replace(path.name, name)
    return preset


def written_bytes(write, suffix: str) -> bytes:
    """What `write(path)` puts in a temporary file with `suffix` (for a download)."""
    fd, tmp = tempfile.mkstemp(prefix="somwidget-", suffix=suffix)
    os.close(fd)
    try:
        write(tmp)
        return Path(tmp).read_bytes()
    finally:
        os.remove(tmp)
