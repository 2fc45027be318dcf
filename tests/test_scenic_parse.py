"""The per-process cache of Scenic parse trees (scenario_bank.scenic_parse)."""

import ast

import pytest
from scenic.core.errors import ScenicParseError

from scenario_bank.scenic_parse import install_parse_cache, parse_scenic

SOURCE = "param speed = Range(5, 10)\nx = 3\n"


def test_same_text_parses_once_and_errors_are_not_cached():
    assert parse_scenic(SOURCE) is parse_scenic(SOURCE, "other.scenic")
    with pytest.raises(ScenicParseError):
        parse_scenic("x = = 1\n", "bad.scenic")
    with pytest.raises(ScenicParseError):
        parse_scenic("x = = 1\n", "bad.scenic")


def test_compiler_gets_copies_it_may_rewrite():
    from scenic.syntax import translator

    install_parse_cache()
    install_parse_cache()  # idempotent: one wrapper
    assert getattr(translator.parse_string, "dv2s_cached", False)
    first = translator.parse_string(SOURCE, "exec", filename="a.scenic")
    first.body.clear()  # what Scenic's compiler does to a tree must not reach the cache
    second = translator.parse_string(SOURCE, "exec", filename="a.scenic")
    assert len(second.body) == 2
    assert ast.dump(second) == ast.dump(parse_scenic(SOURCE))


def test_two_scripts_sharing_the_model_compile_and_sample():
    from envs.scenarios import compile_scenario

    for k in range(2):
        script = ("param map = 'highway_straight'\nmodel scenic.domains.driving.model\n"
                  f"ego = new Car on road, with speed {10 + k}\n")
        scene = compile_scenario(script, name=f"parse_cache_{k}").sample(0)
        assert scene.egoObject.speed == 10 + k
