"""Bad input given to the public API is refused with a project error (a :class:`DV2SError`, which the command line
reports as one line naming the fix) that is still the built-in exception callers catch."""

from __future__ import annotations

import pytest

from dv2s_gym.mining.sampling.checkpoint_mac import DamagedKeyError
from dv2s_gym.pipeline.semantics.text import parse_description
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.pytest_plugin import regression_arguments
from dv2s_gym.regress.stats import wilson_interval
from envs.dv2s_env import resolve_scenarios
from scenario_bank.bank import Bank
from scenario_bank.errors import DV2SError, WrongTypeError
from scenario_bank.maps import resolve_map


@pytest.mark.parametrize("call, builtin, words", [
    (lambda tmp: resolve_scenarios(42), TypeError, "scenario must be None, a bank name"),
    (lambda tmp: resolve_map(3.5), TypeError, "map must be a name or a path"),
    (lambda tmp: parse_description(b"a car"), TypeError, "description must be a string"),
    (lambda tmp: Bank(tmp / "bank").add("ego = new Car", 7), TypeError, "Sidecar or its description as a string"),
    (lambda tmp: regression_arguments("rule", baseline="idm", episode=3), TypeError, "pass only the settings"),
    (lambda tmp: wilson_interval(5, 3), ValueError, "need 0 <= k <= n"),
])
def test_bad_input_to_the_public_api_is_a_project_error_and_still_the_builtin(tmp_path, call, builtin, words):
    with pytest.raises(DV2SError, match=words) as caught:
        call(tmp_path)
    assert isinstance(caught.value, builtin)


def test_the_project_errors_keep_their_builtin():
    assert issubclass(WrongTypeError, TypeError) and issubclass(RegressError, ValueError)
    assert issubclass(DamagedKeyError, OSError) and issubclass(DamagedKeyError, DV2SError)
