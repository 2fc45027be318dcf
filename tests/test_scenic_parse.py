"""The per-process cache of Scenic parse trees (scenario_bank.scenic_parse)."""

import ast
from pathlib import Path

import pytest
from scenic.core.errors import ScenicParseError

from scenario_bank.scenic_parse import install_parse_cache, parse_scenic

pytestmark = pytest.mark.usefixtures("in_process_simulator")

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


# --------------------------------------------------------------------------- on-disk cache of library trees


def _fresh_process_cache(monkeypatch, tmp_path):
    import scenario_bank.scenic_parse as sp

    monkeypatch.setenv("DV2S_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(sp, "_PARSED", type(sp._PARSED)())  # as in a new process
    return sp


@pytest.mark.slow
def test_library_trees_are_kept_on_disk_and_read_back(monkeypatch, tmp_path):
    import scenic

    from scenic.syntax.parser import parse_string

    sp = _fresh_process_cache(monkeypatch, tmp_path)
    path = Path(scenic.__file__).parent / "domains" / "driving" / "behaviors.scenic"
    source = path.read_text()
    first = sp.parse_scenic(source, str(path))
    files = list((tmp_path / "scenic-parse").glob("*.pickle"))
    assert len(files) == 1
    sp = _fresh_process_cache(monkeypatch, tmp_path)
    monkeypatch.setattr("scenic.syntax.parser.parse_string", lambda *a, **k: pytest.fail("parsed again"))
    second = sp.parse_scenic(source, str(path))
    assert ast.dump(second, include_attributes=True) == ast.dump(first, include_attributes=True)
    assert ast.dump(second) == ast.dump(parse_string(source, "exec", filename=str(path)))


def test_other_scripts_never_reach_the_disk(monkeypatch, tmp_path):
    sp = _fresh_process_cache(monkeypatch, tmp_path)
    script = tmp_path / "user.scenic"
    script.write_text(SOURCE)
    sp.parse_scenic(SOURCE, str(script))
    sp.parse_scenic(SOURCE + "y = 1\n")
    assert not list(tmp_path.rglob("*.pickle"))


@pytest.mark.slow
def test_foreign_or_corrupt_cache_files_are_ignored(monkeypatch, tmp_path):
    import os
    import pickle

    import scenic

    sp = _fresh_process_cache(monkeypatch, tmp_path)
    path = Path(scenic.__file__).parent / "domains" / "driving" / "model.scenic"
    source = path.read_text()
    target = sp.cache_dir() / f"{sp._disk_key(source)}.pickle"
    target.parent.mkdir(parents=True)
    marker = tmp_path / "executed"

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    for content in (pickle.dumps(Payload()), b"\x80\x05garbage", pickle.dumps([1, 2])):
        target.write_bytes(content)
        sp = _fresh_process_cache(monkeypatch, tmp_path)
        tree = sp.parse_scenic(source, str(path))
        assert isinstance(tree, ast.Module) and tree.body
        assert not marker.exists()
