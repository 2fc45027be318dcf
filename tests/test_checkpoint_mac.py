"""Sampler checkpoints are sealed with the user's own key: one not written by this user's dv2s-gym is
never unpickled."""

from __future__ import annotations

import os
import pickle
import stat

import pytest

from dv2s_gym.mining.sampling import checkpoint_mac
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.sampling.samplers import SceneSampler
from dv2s_gym.mining.sampling.window import WindowSchedule


class _Planted:
    def __reduce__(self):
        return (os.system, (f"touch {os.environ['DV2S_TEST_MARKER']}",))


@pytest.fixture
def state(tmp_path, monkeypatch):
    folder = tmp_path / "state"
    monkeypatch.setattr(checkpoint_mac, "state_dir", lambda: folder)
    monkeypatch.setenv("DV2S_TEST_MARKER", str(tmp_path / "unpickled"))
    return folder


def test_the_key_is_made_once_private_to_the_user(state):
    sealed = checkpoint_mac.seal(b"payload")
    key = state / "checkpoint.key"
    assert stat.S_IMODE(key.stat().st_mode) == 0o600 and len(key.read_bytes()) == 32
    assert checkpoint_mac.unseal(sealed) == b"payload"
    assert checkpoint_mac.seal(b"payload") == sealed  # the same key on the next use


@pytest.mark.parametrize("load", [SceneSampler.loads, WindowSchedule.loads])
def test_an_unsealed_pickle_is_refused_without_unpickling(state, tmp_path, load):
    with pytest.raises(MiningError, match="not written by this user's dv2s-gym.*another --out"):
        load(pickle.dumps(_Planted()))
    assert not (tmp_path / "unpickled").exists()


@pytest.mark.parametrize("load", [SceneSampler.loads, WindowSchedule.loads])
def test_a_checkpoint_sealed_with_another_key_or_altered_is_refused(state, tmp_path, load):
    sealed = checkpoint_mac.seal(pickle.dumps(_Planted()))
    altered = sealed[:-1] + bytes([sealed[-1] ^ 1])
    (state / "checkpoint.key").unlink()  # another user's key: this one is new
    for data in (sealed, altered):
        with pytest.raises(MiningError, match="no valid MAC"):
            load(data)
    assert not (tmp_path / "unpickled").exists()
