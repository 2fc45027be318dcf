"""``--dra``/``--sg`` accept every backend in the pipeline's registries, on every command that has them."""

import json

import pytest

from dv2s_gym.cli import build_parser, main
from dv2s_gym.pipeline import stages
from dv2s_gym.pipeline.evaluate import EVALSET_DIR

CLIP = EVALSET_DIR / "highway_lead_vehicle_brakes_seed0.webm"
TEXT = "A car ahead of the ego brakes on a highway."


@pytest.fixture
def fixed_dra(monkeypatch):
    """A DRA backend ``fixed`` registered (as a plugin would) before ``main`` runs; the registries restored after."""
    monkeypatch.setattr(stages, "_DRA_REGISTRY", stages._DRA_REGISTRY.copy())
    monkeypatch.setattr(stages, "_SG_REGISTRY", stages._SG_REGISTRY.copy())
    calls = []

    def fixed(clip, *, camera, question, llm_config):
        calls.append((len(clip.frames), camera, question))
        return TEXT, {"model": "fixed-1"}

    stages.register_dra("fixed", fixed)
    return calls


def _usage_error(capsys, argv):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1, err
    return err


def test_describe_runs_a_registered_dra_backend(capsys, fixed_dra):
    code = main(["describe", str(CLIP), "--dra", "fixed", "--camera", "front", "--max-frames", "3", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert fixed_dra == [(3, "front", None)]
    assert (out["text"], out["backend"], out["model"]) == (TEXT, "fixed", "fixed-1")
    assert out["elements"]["road"] == "highway"


def test_a_misspelt_registered_backend_is_one_line_with_a_suggestion(capsys, fixed_dra):
    err = _usage_error(capsys, ["describe", str(CLIP), "--dra", "fixd"])
    assert err.startswith("dv2s describe: error: argument --dra: invalid choice: 'fixd' "
                          "(choose from 'bev', 'openai', 'fixed'); did you mean 'fixed'?")
    err = _usage_error(capsys, ["eval", "sg", "--sg", "rule"])
    assert "invalid choice: 'rule'" in err and "did you mean 'rules'?" in err
    err = _usage_error(capsys, ["mine", "--policy", "rule", "--dra", "zzz"])
    assert "invalid choice: 'zzz'" in err and "did you mean" not in err


def test_an_unregistered_backend_is_refused(capsys):
    err = _usage_error(capsys, ["describe", str(CLIP), "--dra", "fixed"])
    assert "invalid choice: 'fixed' (choose from 'bev', 'openai')" in err


@pytest.mark.parametrize("command", [["describe"], ["convert"], ["eval"], ["mine"], ["generate"]])
def test_every_command_lists_the_registered_backends(command, fixed_dra):
    stages.register_sg("mine-sg", lambda description, **options: None)
    help_text = _help(command)
    if command != ["generate"]:
        assert "--dra {bev,openai,fixed}" in help_text and "also registered: fixed" in help_text
    if command != ["describe"]:
        assert "--sg {rules,openai,mine-sg}" in help_text and "also registered: mine-sg" in help_text


def test_the_choices_are_read_when_the_command_line_is_parsed(fixed_dra):
    parser = build_parser()
    stages.register_dra("later", lambda clip, **options: ("", {}))
    assert parser.parse_args(["describe", "v.mp4", "--dra", "later"]).dra == "later"


def _help(command):
    parser = build_parser()
    sub = next(action for action in parser._actions if action.dest == "command")
    return " ".join(sub.choices[command[0]].format_help().split())  # unwrapped


def _model_error(capsys, argv):
    """The one error line of ``dv2s ARGV`` refused for a model option no chosen backend reads (exit 2)."""
    try:
        code = main(argv)
    except SystemExit as stop:
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_model_options_for_backends_that_call_no_model_are_refused_before_any_work(capsys, tmp_path):
    err = _model_error(capsys, ["generate", TEXT, "--model", "gpt-x", "--out", str(tmp_path / "gen")])
    assert "--model sets the model a backend calls, and --sg rules calls none" in err
    assert "drop it, or choose a backend that calls a model (--sg openai)" in err
    assert not (tmp_path / "gen").exists()
    err = _model_error(capsys, ["describe", str(CLIP), "--api-key", "k", "--base-url", "http://x"])
    assert "--base-url, --api-key set the model a backend calls, and --dra bev calls none: drop them" in err
    err = _model_error(capsys, ["convert", str(CLIP), "--model", "m", "--out", str(tmp_path / "c")])
    assert "--dra bev and --sg rules call none" in err and "(--dra openai or --sg openai)" in err


def test_model_options_reach_a_backend_that_calls_a_model(capsys, fixed_dra, monkeypatch):
    seen = []
    stages.register_dra("fixed", lambda clip, *, camera, question, llm_config: seen.append(llm_config) or (TEXT, {}),
                        overwrite=True)  # a plug-in's backend reads the model settings unless it says otherwise
    assert main(["describe", str(CLIP), "--dra", "fixed", "--model", "m-1", "--max-frames", "2", "--json"]) == 0
    assert seen[0].model == "m-1"
    capsys.readouterr()
    stages.register_dra("fixed", lambda clip, **options: (TEXT, {}), overwrite=True, reads_model=False)
    err = _model_error(capsys, ["describe", str(CLIP), "--dra", "fixed", "--model", "m-1"])
    assert "--dra fixed calls none" in err
    # with one backend that calls a model, the options are for it
    assert stages.reads_model("SG", "openai") and not stages.reads_model("SG", "rules")


@pytest.mark.parametrize("command", [["describe"], ["convert"], ["eval"], ["mine"], ["generate"]])
def test_the_model_options_are_their_own_group_of_the_help(command):
    parser = build_parser()
    sub = next(action for action in parser._actions if action.dest == "command")
    text = sub.choices[command[0]].format_help()
    start = text.index("\nmodel endpoint:\n")
    model, options = text[start:], text[text.index("\noptions:\n"):start]  # the group comes after the options
    for name in ("--base-url", "--model", "--api-key"):
        assert name in model and name not in options
