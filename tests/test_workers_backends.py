"""Worker backends by name: one table read by get_backend, by ``--backend`` of the commands and by the pytest plugin."""

from __future__ import annotations

import pytest

from dv2s_gym.cli import build_parser
from dv2s_gym.workers import backends
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.pool import LocalBackend


class _Recorded:
    """A stand-in backend that keeps what it was made with."""

    def __init__(self, **options):
        self.options = options


@pytest.fixture
def table(monkeypatch):
    """The table as shipped, restored after the test."""
    monkeypatch.setattr(backends, "_FACTORIES", backends._FACTORIES.copy())


def test_the_shipped_backends_are_in_the_table():
    assert backends.BACKENDS == ("local", "ray")
    assert backends.registered_backends() == ["local", "ray"]
    assert list(backends.backend_choices()) == ["local", "ray"]


def test_get_backend_makes_a_local_pool_and_refuses_an_address_for_it():
    pool = backends.get_backend("local", workers=1, timeout=5.0)
    try:
        assert isinstance(pool, LocalBackend) and pool.workers == 1
    finally:
        pool.close()
    with pytest.raises(WorkerError, match="--address is for --backend ray"):
        backends.get_backend("local", address="head:6379")


def test_a_registered_backend_is_made_by_get_backend_and_accepted_by_the_commands(table):
    backends.register_backend("recorded", _Recorded)
    made = backends.get_backend("recorded", workers=3, address="a:1", timeout=2.0)
    assert isinstance(made, _Recorded) and made.options == {"workers": 3, "address": "a:1", "timeout": 2.0}
    parser = build_parser()
    assert parser.parse_args(["regress", "--policy", "rule", "--backend", "recorded"]).backend == "recorded"
    assert parser.parse_args(["mine", "--policy", "rule", "--backend", "recorded"]).backend == "recorded"
    with pytest.raises(WorkerError, match=r"^unknown backend 'slurm': use 'local', 'ray' or 'recorded'$"):
        backends.get_backend("slurm")


def test_registering_a_taken_or_empty_name_is_refused(table):
    with pytest.raises(WorkerError, match="a worker backend named 'local' is already registered; pass overwrite=True"):
        backends.register_backend("local", _Recorded)
    with pytest.raises(WorkerError, match="worker backend name '' must be a non-empty string"):
        backends.register_backend("", _Recorded)
    backends.register_backend("local", _Recorded, overwrite=True)
    assert isinstance(backends.get_backend("local"), _Recorded)


def test_an_unknown_backend_on_the_command_line_is_one_line_with_a_suggestion(capsys):
    from dv2s_gym.cli import main

    with pytest.raises(SystemExit) as stop:
        main(["regress", "--policy", "rule", "--backend", "rey"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1
    assert "argument --backend: invalid choice: 'rey' (choose from 'local', 'ray'); did you mean 'ray'?" in err
