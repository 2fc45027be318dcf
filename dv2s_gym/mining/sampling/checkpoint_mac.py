"""Authenticating the sampler checkpoints a mining run writes (``sampler.pkl``).

A checkpoint is a pickle, and unpickling runs code: one planted in a run folder would run in the
user's process on resume. Each checkpoint is therefore sealed with an HMAC-SHA256 keyed by a secret
kept in the user's own state folder (``platformdirs.user_state_dir("dv2s-gym")/checkpoint.key``,
mode 0600, created on first use); only a checkpoint carrying a valid MAC is unpickled.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from pathlib import Path
from platformdirs import user_state_dir
from typing import Optional

from scenario_bank.errors import DV2SError

__all__ = ["MAGIC", "DamagedKeyError", "key_path", "seal", "unseal"]

MAGIC = b"DV2S-HMAC-SHA256\n"
"""The header of a sealed checkpoint: ``MAGIC``, the 32-byte MAC, then the pickle."""
_KEY_BYTES = 32


class DamagedKeyError(DV2SError, OSError):
    """The key that seals the sampler checkpoints is not a key (truncated, or written over); the message names the
    file and says to delete it. An :class:`OSError`, as a file that cannot be read is."""


def state_dir() -> Path:
    """The user's dv2s-gym state folder (where the checkpoint key lives)."""
    return Path(user_state_dir("dv2s-gym"))


def key_path() -> Path:
    """Where this user's checkpoint key is kept."""
    return state_dir() / "checkpoint.key"


def _key() -> bytes:
    path = key_path()
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    except FileExistsError:
        pass
    else:
        try:
            os.write(fd, secrets.token_bytes(_KEY_BYTES))
        finally:
            os.close(fd)
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    try:
        key = os.read(fd, _KEY_BYTES + 1)
    finally:
        os.close(fd)
    if len(key) != _KEY_BYTES:
        raise DamagedKeyError(f"the checkpoint key {path} is damaged ({len(key)} bytes, not {_KEY_BYTES}); delete it "
                              "(checkpoints written with it are then rebuilt from the runs' episodes.jsonl)")
    return key


def _mac(payload: bytes) -> bytes:
    return hmac.new(_key(), payload, hashlib.sha256).digest()


def seal(payload: bytes) -> bytes:
    """``payload`` with this user's MAC in front (what :func:`unseal` accepts)."""
    return MAGIC + _mac(payload) + payload


def unseal(data: bytes) -> Optional[bytes]:
    """The payload of a checkpoint sealed by :func:`seal` with this user's key, or ``None`` when ``data``
    carries no MAC or a wrong one (not written by this user's dv2s-gym, or altered since)."""
    head = len(MAGIC) + hashlib.sha256().digest_size
    if len(data) < head or not data.startswith(MAGIC):
        return None
    mac, payload = data[len(MAGIC):head], data[head:]
    return payload if hmac.compare_digest(mac, _mac(payload)) else None
