"""The product's task kinds are built-in entries: a plug-in that replaces how every regression or mining episode
runs is said, as a replaced detector is."""

from __future__ import annotations

import warnings

import pytest

from dv2s_gym.mining import tasks as mining_tasks
from dv2s_gym.regress import tasks as regress_tasks
from dv2s_gym.workers.tasks import function_for, mark_built_in, register
from scenario_bank.errors import BuiltInReplacedWarning
from scenario_bank.named_registry import replaced_built_ins

__all__: list = []


def run_nothing(task):
    """A plug-in's replacement of a task kind."""
    return {}


@pytest.mark.parametrize("kind, function", [("regress", regress_tasks.run_regress_task),
                                            ("mine", mining_tasks.run_mine_task)])
def test_replacing_a_product_task_kind_warns_and_is_listed(kind, function):
    try:
        with pytest.warns(BuiltInReplacedWarning, match=f"task kind '{kind}' was replaced"):
            register(kind, run_nothing, overwrite=True)
        assert function_for({"kind": kind}) is run_nothing
        assert f"task kind '{kind}' (replaced by {__name__})" in replaced_built_ins()
    finally:
        register(kind, function, overwrite=True)
        mark_built_in(kind)
    assert not [entry for entry in replaced_built_ins() if entry.startswith("task kind")]


def test_registering_a_kind_with_its_own_function_again_is_no_replacement():
    """As when its module is imported a second time."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", BuiltInReplacedWarning)
        register("regress", regress_tasks.run_regress_task)
    assert function_for({"kind": "regress"}) is regress_tasks.run_regress_task
    assert not [entry for entry in replaced_built_ins() if entry.startswith("task kind")]
