"""Where expensive results are cached: $SOFTCATH_CACHE, else .cache/ in the source tree or the
user's cache directory. Keys are hashes of every input that changes the result."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path


def cache_dir(kind: str) -> Path:
    """The cache directory for one kind of result (created on demand)."""
    root = os.environ.get("SOFTCATH_CACHE")
    if root:
        base = Path(root)
    else:
        repo = Path(__file__).resolve().parents[2]
        base = repo / ".cache" if (repo / "setup.py").is_file() else Path.home() / ".cache" / "softcath_ros"
    path = base / kind
    path.mkdir(parents=True, exist_ok=True)
    return path


def key_of(*parts) -> str:
    """A stable 16-hex-digit hash of JSON-serialisable parts."""
    blob = json.dumps(parts, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]
