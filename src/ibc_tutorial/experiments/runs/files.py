"""A study folder's files, each checked as it is read: JSON, compressed arrays, checkpoints.

Every study of the command line writes its files through these functions (atomically) and reads them
back through them: a damaged file is a ``ValueError`` naming it and saying what to do (``fix``), never
a traceback from ``json`` or ``numpy``. Checkpoints are read with ``torch.load(..., weights_only=True)``.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.utils import atomic_write_bytes

PROVENANCE = "provenance.json"
"""How, where and when a folder's results were made (``PROVENANCE.md`` says the same for readers)."""
PROVENANCE_MD = "PROVENANCE.md"
"""The readers' copy of ``provenance.json``."""
RESULTS = "results.json"
"""A finished folder's tables and numbers: the file its chapter reads (every study's folder holds one)."""


def write_json(path, obj) -> Path:
    """``obj`` as indented JSON, written atomically."""
    return atomic_write_bytes(path, json.dumps(obj, indent=1).encode())


def read_json(path, fix: str):
    """A JSON file's content; ValueError naming the file and ``fix`` (what to do) if it is not JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is damaged, not readable JSON ({type(exc).__name__}): {fix}") from None


def read_json_dict(path, fix: str) -> dict:
    """A JSON file that must hold a dict; ValueError naming the file and ``fix`` (what to do) otherwise."""
    obj = read_json(path, fix)
    if not isinstance(obj, dict):
        raise ValueError(f"{path} is damaged: it holds a {type(obj).__name__}, not a JSON object: {fix}")
    return obj


def write_npz(path, arrays: dict) -> Path:
    """Arrays as a compressed ``.npz``, written atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())


def read_npz(path, fix: str) -> dict:
    """The arrays of a ``.npz`` file as a dict; ValueError naming the file and ``fix`` if it is damaged."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:  # zip, zlib, format errors of a truncated or altered file
        raise ValueError(f"{path} is truncated or damaged ({type(exc).__name__}): {fix}") from None


def read_torch_file(path, what: str, fix: str) -> dict:
    """A checkpoint file read with ``torch.load(..., weights_only=True)`` onto the CPU: plain data only,
    no pickled code runs. Its errors are one ValueError naming the file, ``what`` it should be (e.g.
    "agent checkpoint") and ``fix`` (never torch's advice to load with ``weights_only=False``: that
    would run code stored in the file). Both studies' checkpoints are read here."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder, expected a file ({what})")
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        text = str(exc)
        if "weights_only" in text or "Unsupported global" in text:
            why = "it holds Python objects, not only tensors and plain data (refused: loading them runs code)"
        elif "zip" in text.lower() or "central directory" in text or isinstance(exc, (EOFError, OSError)):
            why = "it is truncated or damaged"
        else:
            why = f"{type(exc).__name__}: {' '.join(text.split()[:16])}"
        raise ValueError(f"{path} is not a readable {what} ({why}): {fix}") from None


def read_run_file(path, valid, what: str) -> dict:
    """A run's JSON file, checked by ``valid(d)`` (called on a dict only); ValueError naming the file, what it
    should be (``what``, e.g. "a run's evaluation") and how to make it again otherwise."""
    path = Path(path)
    fix = f"delete {path.parent} and re-run the same command to make that run again"
    d = read_json(path, fix)
    if not isinstance(d, dict) or not valid(d):
        raise ValueError(f"{path} is damaged (not {what}): {fix}")
    return d
