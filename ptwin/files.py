"""Files ptwin writes and reads back (PGD bases, checkpoints): atomic, checksummed, and
refused with one line when they are not what they claim to be.

On disk a file is one header line ``ptwin sha256=<hex digest of the rest>`` followed by
``torch.save`` of a plain dict (tensors and built-in types) that names its ``format``.
Written to a temporary file and renamed, so a kill leaves the previous file whole; any
flipped byte fails the checksum; ``torch.load(weights_only=True)`` runs no code.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path

import torch

MAGIC = b"ptwin sha256="


class StoredFileError(ValueError):
    """A stored file that cannot be used; the message is the one line to show."""


def save(path: str | Path, payload: dict) -> None:
    """Write ``payload`` (a dict with a ``format`` key) atomically, with its checksum."""
    if "format" not in payload:
        raise ValueError("a stored payload names its format")
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    body = buffer.getvalue()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_bytes(MAGIC + hashlib.sha256(body).hexdigest().encode() + b"\n" + body)
    os.replace(temporary, path)


def load(
    path: str | Path, format: str, remedy: str, label: str | None = None, error: type[Exception] = StoredFileError
) -> dict:
    """The payload stored at ``path``, checked whole; otherwise ``error`` with one line.

    Args:
        format: the format the payload must name.
        remedy: what the user should do, ending every message (e.g. "rebuild it with ...").
        label: how the message names the file (default: its path).
    """
    label = label or str(path)
    path = Path(path)
    if not path.is_file():
        raise error(f"{label}: no such file; {remedy}")
    header, newline, body = path.read_bytes().partition(b"\n")
    if not header.startswith(MAGIC) or not newline:
        raise error(f"{label}: not a ptwin file (no checksum header); {remedy}")
    if hashlib.sha256(body).hexdigest().encode() != header[len(MAGIC) :]:
        raise error(f"{label}: checksum mismatch, the file is damaged; {remedy}")
    try:
        payload = torch.load(io.BytesIO(body), weights_only=True)
    except Exception as failure:  # the zip reader raises many kinds on a damaged file
        raise error(f"{label}: not readable ({failure.__class__.__name__}); {remedy}") from None
    found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
    if found != format:
        raise error(f"{label}: format {found!r}, this ptwin reads {format!r}; {remedy}")
    return payload
