"""One notion of "the same run" for every resumable run kind: a resume over an edited bank script, other or changed
plug-ins (their detectors, failure types and sources, the built-ins they replace, the user's modules they load, the
modules that registered a sampler) or a changed reference driver is refused in one line naming what differs and the
fix; an unchanged resume resumes.

``dv2s loop`` is checked in ``tests/test_loop.py`` (its stand-ins live there); ``dv2s regress`` records the same
code and bank identities under the same keys and refuses in the same words (``tests/test_regress_inputs.py`` and
below)."""

from __future__ import annotations

import importlib
import json
import re
import sys
import types
import warnings

import pytest

import policies.run_identity as run_identity
from mining_helpers import SpaceBuilt, mine, recorded_run_folder
from regress_call import run_regression
from dv2s_gym.mining import monitors
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.regress.errors import ResumeMismatchError
from policies.run_identity import CODE_IDENTITY, code_identity
from policies.training import TrainConfig, run_settings, train
from scenario_bank.bank import Bank
from scenario_bank.errors import BuiltInReplacedWarning
from scenario_bank.named_registry import replaced_built_ins
from scenario_bank.plugins import check_plugins, plugin_modules
from scenario_bank.run_identity import BANK_IDENTITY, RunIdentityError, bank_identity

SCENARIO = "highway_lead_vehicle_brakes"
PLUGIN = "identity_probe_plugin"
PLUGIN_SOURCE = '''
from dv2s_gym.mining.monitors import Detector, register_detector, unregister_detector
from scenario_bank.failure_types import FailureType, register_failure_type, unregister_failure_type

NAME = "identity_probe"
LIMIT = {limit}


def detect(result, trace, settings):
    return None


register_failure_type(FailureType(NAME, severity=40, result_field=None, regress_default=False, with_actor=False,
                                  label=None))
register_detector(Detector(NAME, detect, lambda result, failure, settings: -1.0))


def unregister():
    unregister_detector(NAME)
    unregister_failure_type(NAME)
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A plug-in module (a failure type and its detector) in a folder on the Python path, imported; undone after."""
    folder = tmp_path / "plugins"
    folder.mkdir()
    path = folder / f"{PLUGIN}.py"
    path.write_text(PLUGIN_SOURCE.format(limit=1), encoding="utf-8")
    monkeypatch.syspath_prepend(str(folder))
    module = importlib.import_module(PLUGIN)
    yield path
    module.unregister()
    sys.modules.pop(PLUGIN, None)


HELPED = "identity_probe_helped_plugin"
HELPER = "identity_probe_helper"


@pytest.fixture
def helped_plugin(tmp_path, monkeypatch):
    """A plug-in module whose detector's limit lives in a helper module of another folder on the Python path (a
    ``lib/`` of the user's), imported; the helper's path is yielded, the plug-in undone after."""
    lib, folder = tmp_path / "lib", tmp_path / "plugins"
    lib.mkdir()
    folder.mkdir()
    helper = lib / f"{HELPER}.py"
    helper.write_text("LIMIT = 1\n", encoding="utf-8")
    (folder / f"{HELPED}.py").write_text(f"import {HELPER}\n" + PLUGIN_SOURCE.format(limit=f"{HELPER}.LIMIT"),
                                         encoding="utf-8")
    monkeypatch.syspath_prepend(str(lib))
    monkeypatch.syspath_prepend(str(folder))
    module = importlib.import_module(HELPED)
    yield helper
    module.unregister()
    sys.modules.pop(HELPED, None)
    sys.modules.pop(HELPER, None)


@pytest.fixture
def replaced_collision(monkeypatch):
    """A function that replaces the built-in ``collision`` detector (in a copy of the registry, undone after; not
    used with :func:`plugin`, whose registration would stay in the copy)."""
    monkeypatch.setattr(monitors, "DETECTORS", monitors.DETECTORS.copy())

    def replace() -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BuiltInReplacedWarning)
            monitors.register_detector(monitors.Detector("collision", lambda *a: None, lambda *a: 0.0),
                                       overwrite=True)
    yield replace
    if "collision" in monitors.DETECTORS and monitors.DETECTORS.module("collision") == __name__:
        monitors.unregister_detector("collision")


def _mine_settings_folder(folder):
    mine("rule", out=folder, budget=2, scenarios=(SCENARIO,), seed=0, progress=False, reports=False)


# --------------------------------------------------------------------------- the identities themselves
def test_the_code_identity_names_the_plugins_their_registrations_and_the_sources(plugin):
    facts = code_identity()
    assert facts["plug-in modules"] == [PLUGIN]
    assert facts["failure types"] == {"identity_probe": PLUGIN}
    assert facts["detectors"] == {"identity_probe": PLUGIN}
    assert facts[f"module {PLUGIN} source (SHA-256)"] == run_identity.file_sha256(plugin)
    assert len(facts["dv2s sources (SHA-256)"]) == 64 and facts["replaced built-ins"] == []


def test_the_code_identity_names_a_replaced_builtin(replaced_collision):
    assert code_identity()["replaced built-ins"] == []
    replaced_collision()
    assert code_identity()["replaced built-ins"] == [f"detector 'collision' (replaced by {__name__})"]
    assert replaced_built_ins() == [f"detector 'collision' (replaced by {__name__})"]


def test_the_bank_identity_is_each_scripts_sha256(tmp_path):
    bank = Bank().copy_to(tmp_path / "bank")
    before = bank_identity(bank, [SCENARIO, SCENARIO])
    assert list(before) == [SCENARIO] and before[SCENARIO] == run_identity.file_sha256(
        tmp_path / "bank" / SCENARIO / "scenario.scenic")


# --------------------------------------------------------------------------- dv2s mine
def test_a_mining_resume_with_a_changed_or_missing_plugin_is_refused_naming_it(plugin, tmp_path, monkeypatch):
    folder = recorded_run_folder(tmp_path / "mine", (SCENARIO,), monkeypatch)
    with pytest.raises(SpaceBuilt):  # unchanged: past every check made before the space is built
        _mine_settings_folder(folder)
    original = plugin.read_text(encoding="utf-8")
    plugin.write_text(PLUGIN_SOURCE.format(limit=2), encoding="utf-8")  # the detector's module was edited
    with pytest.raises(MiningError) as error:
        _mine_settings_folder(folder)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{folder} holds a mining run made with other code "
                                                      "(plug-in modules' source differ: module identity_probe_plugin")
    assert message.endswith("restore the code the run used (dv2s's sources, the plug-in modules DV2S_PLUGINS "
                            "names, the files they read), or start a new --out folder")
    plugin.write_text(original, encoding="utf-8")
    with pytest.raises(SpaceBuilt):
        _mine_settings_folder(folder)
    sys.modules[PLUGIN].unregister()  # the same run without the plug-in
    with pytest.raises(MiningError, match=r"made with other code \(plug-in modules, plug-in modules' source, "
                                          r"failure types, detectors differ: "):
        _mine_settings_folder(folder)
    importlib.reload(sys.modules[PLUGIN])  # registered again, for the fixture to undo


def test_a_plugins_helper_module_in_another_folder_is_fingerprinted_and_its_edit_refuses_a_resume(
        helped_plugin, tmp_path, monkeypatch):
    key = f"module file {helped_plugin.name} (SHA-256)"  # relative to the Python path's folder holding it
    before = code_identity()
    assert before["plug-in modules"] == [HELPED] and before[key] == run_identity.file_sha256(helped_plugin)
    folder = recorded_run_folder(tmp_path / "mine", (SCENARIO,), monkeypatch)
    with pytest.raises(SpaceBuilt):  # unchanged: past every check made before the space is built
        _mine_settings_folder(folder)
    helped_plugin.write_text("LIMIT = 1000\n", encoding="utf-8")  # the limit the detector uses, edited
    assert code_identity()[key] == run_identity.file_sha256(helped_plugin) != before[key]
    with pytest.raises(MiningError) as error:
        _mine_settings_folder(folder)
    assert str(error.value).startswith(f"{folder} holds a mining run made with other code (plug-in modules' source "
                                       f"differ: {key}: run has {before[key][:12]}, now ")


def test_a_loaded_module_the_run_did_not_have_is_not_compared_and_a_recorded_one_is_hashed_again(helped_plugin,
                                                                                                    tmp_path):
    """A resume compares the user's files as the run recorded them: one loaded since (a notebook's helper) is left
    out, one the run had loaded is hashed again even when this process has not loaded it."""
    recorded_file = tmp_path / "recorded_helper.py"
    recorded_file.write_text("X = 1\n", encoding="utf-8")
    recorded_key = f"module file {recorded_file.resolve()} (SHA-256)"
    now = code_identity()
    extra = [key for key in now if key.startswith("module file ")]
    assert f"module file {helped_plugin.name} (SHA-256)" in extra and recorded_key not in now
    recorded = {CODE_IDENTITY: {**{k: v for k, v in now.items() if k not in extra},
                                recorded_key: run_identity.file_sha256(recorded_file)}}
    run_identity.check_code_unchanged(recorded, run="out holds a mining run", error=MiningError, now=now)
    recorded_file.write_text("X = 2\n", encoding="utf-8")
    with pytest.raises(MiningError, match=f"plug-in modules' source differ: {re.escape(recorded_key)}: run has "):
        run_identity.check_code_unchanged(recorded, run="out holds a mining run", error=MiningError, now=now)
    recorded_file.unlink()
    with pytest.raises(MiningError, match=r"\(SHA-256\): run has [0-9a-f]{12}, now missing\)"):
        run_identity.check_code_unchanged(recorded, run="out holds a mining run", error=MiningError, now=now)


SAMPLER_SOURCE = '''
from dv2s_gym.mining.sampling.samplers import SamplerRecord, register_sampler, registered_samplers

UPPER = {upper}


def build(space, feature_space, params):
    return None


register_sampler("identity_probe_upper", SamplerRecord(build))
'''


@pytest.fixture
def sampler_registry(monkeypatch):
    """The sampler registry as a copy, dropped after the test."""
    from dv2s_gym.mining.sampling import samplers

    monkeypatch.setattr(samplers, "_REGISTRY", samplers._REGISTRY.copy())


def test_a_module_that_registered_a_sampler_is_part_of_the_code_identity_not_of_the_workers_imports(
        sampler_registry, tmp_path, monkeypatch):
    module = "identity_probe_sampler"
    path = tmp_path / f"{module}.py"
    path.write_text(SAMPLER_SOURCE.format(upper=0.5), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, module, raising=False)
    importlib.import_module(module)
    key = f"module {module} source (SHA-256)"
    before = code_identity()
    assert before["plug-in modules"] == [module] and before[key] == run_identity.file_sha256(path)
    assert plugin_modules() == check_plugins() == []  # the workers are not asked to import it
    recorded = {CODE_IDENTITY: before}
    run_identity.check_code_unchanged(recorded, run="out holds a mining run", error=MiningError)
    path.write_text(SAMPLER_SOURCE.format(upper=0.9), encoding="utf-8")  # the sampler edited
    assert code_identity()[key] == run_identity.file_sha256(path) != before[key]
    with pytest.raises(MiningError, match=r"^out holds a mining run made with other code \(plug-in modules' source "
                                          f"differ: {re.escape(key)}: run has "):
        run_identity.check_code_unchanged(recorded, run="out holds a mining run", error=MiningError)
    sys.modules.pop(module, None)


def test_a_sampler_registered_in_main_is_fingerprinted_by_the_scripts_file_and_stays_allowed(
        sampler_registry, tmp_path, monkeypatch):
    from dv2s_gym.mining.sampling.samplers import SamplerRecord, register_sampler

    script = tmp_path / "run_mine.py"
    script.write_text("# the user's script\n", encoding="utf-8")
    main = types.ModuleType("__main__")
    main.__file__ = str(script)
    monkeypatch.setitem(sys.modules, "__main__", main)
    exec(compile("register_sampler('from_main', SamplerRecord(lambda space, features, params: None))", str(script),
                 "exec"), {"__name__": "__main__", "register_sampler": register_sampler, "SamplerRecord": SamplerRecord})
    facts = code_identity()
    assert facts["plug-in modules"] == ["__main__"] and check_plugins() == []  # allowed for runs with workers
    assert facts["module __main__ source (SHA-256)"] == run_identity.file_sha256(script)
    script.write_text("# the user's script, edited\n", encoding="utf-8")
    assert code_identity()["module __main__ source (SHA-256)"] == run_identity.file_sha256(script)
    monkeypatch.delattr(main, "__file__")  # python -c, an interactive session: no file to fingerprint
    assert code_identity()["module __main__ source (SHA-256)"] == "not found"


def test_a_mining_resume_after_a_builtin_detector_was_replaced_is_refused(replaced_collision, tmp_path, monkeypatch):
    folder = recorded_run_folder(tmp_path / "mine", (SCENARIO,), monkeypatch)
    replaced_collision()
    with pytest.raises(MiningError, match=r"made with other code \(plug-in modules, plug-in modules' source, "
                                          r"detectors, replaced built-ins differ: detectors: run has \{\}, now "
                                          r"\{'collision'"):
        _mine_settings_folder(folder)


def test_a_mining_resume_with_a_changed_reference_driver_is_refused(tmp_path, monkeypatch):
    folder = recorded_run_folder(tmp_path / "mine", (SCENARIO,), monkeypatch)
    real = run_identity.resume_fingerprint
    path = folder / "settings.json"
    settings = json.loads(path.read_text(encoding="utf-8"))
    assert settings["reference"] == "rule" and settings["reference_fingerprint"] == real("rule")
    settings["policy"], settings["policy_fingerprint"] = "keep_lane", real("keep_lane")  # a run of keep_lane
    path.write_text(json.dumps(settings), encoding="utf-8")

    def keep_lane():
        mine("keep_lane", out=folder, budget=2, scenarios=(SCENARIO,), seed=0, progress=False, reports=False)

    with pytest.raises(SpaceBuilt):  # unchanged
        keep_lane()
    monkeypatch.setattr(run_identity, "resume_fingerprint", lambda spec: {
        **real(spec), **({"module policies.rule_based source (SHA-256)": "0" * 64} if spec == "rule" else {})})
    with pytest.raises(MiningError) as error:
        keep_lane()
    assert str(error.value).startswith(f"{folder} holds a mining run whose reference driver rule has changed since "
                                       "(module policies.rule_based source (SHA-256): run has ")
    assert str(error.value).endswith("now 000000000000); restore the reference driver (its checkpoint or module as "
                                     "the run used it), or pass a new --out")


@pytest.mark.slow
def test_a_mining_resume_over_an_edited_bank_script_is_refused_naming_it(tmp_path):
    bank = tmp_path / "bank"
    Bank().copy_to(bank)
    run = dict(policy="rule", out=tmp_path / "mine", scenarios=(SCENARIO,), bank_dir=str(bank), seed=0,
               convert=False, workers=1, progress=False, reports=False)
    mine(**{**run, "budget": 2})
    assert mine(**{**run, "budget": 3}).records[-1].index == 2  # unchanged: resumed
    recorded = json.loads((tmp_path / "mine" / "settings.json").read_text(encoding="utf-8"))
    assert recorded[BANK_IDENTITY] == bank_identity(Bank(bank), [SCENARIO])
    script = bank / SCENARIO / "scenario.scenic"
    script.write_text(script.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    with pytest.raises(MiningError) as error:
        mine(**{**run, "budget": 4})
    assert str(error.value) == (f"{tmp_path / 'mine'} holds a mining run over other scenario scripts (the bank's "
                                f"script for '{SCENARIO}' changed since the run began); restore the script as the "
                                "run used it, or start a new --out folder")


# --------------------------------------------------------------------------- dv2s train
class _PastTheCheck(Exception):
    pass


def _past_the_check(line: str) -> None:
    if "holds no checkpoint yet" in line:  # past the resume checks (the run had not reached its first checkpoint)
        raise _PastTheCheck()


def _training_folder(tmp_path, bank):
    out = tmp_path / "run"
    out.mkdir()
    config = TrainConfig(out=str(out), algo="ppo", scenarios=(SCENARIO,), bank_dir=str(bank), steps=300, n_envs=1,
                         eval_freq=0, card_seeds=0, checkpoint_freq=0, progress_bar=False, vec_env="dummy")
    (out / "run.json").write_text(json.dumps({
        "schema": "dv2s-train-run", "version": 2, "config": config.to_json(),
        BANK_IDENTITY: bank_identity(Bank(bank), [SCENARIO]), CODE_IDENTITY: code_identity(), "segments": []}),
        encoding="utf-8")
    return out


def _resume_training(out):
    train(run_settings(out, {}, resume=True), resume=True, log=_past_the_check)


def test_a_training_resume_over_an_edited_script_or_other_plugins_is_refused(tmp_path, replaced_collision):
    bank = tmp_path / "bank"
    Bank().copy_to(bank)
    out = _training_folder(tmp_path, bank)
    with pytest.raises(_PastTheCheck):  # unchanged: resumes
        _resume_training(out)
    replaced_collision()
    with pytest.raises(RunIdentityError, match=f"^{out} holds a training run made with other code "
                                               r"\(plug-in modules, plug-in modules' source, detectors, replaced "
                                               r"built-ins differ"):
        _resume_training(out)
    script = bank / SCENARIO / "scenario.scenic"
    script.write_text(script.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    with pytest.raises(RunIdentityError) as error:
        _resume_training(out)
    assert str(error.value) == (f"{out} holds a training run over other scenario scripts (the bank's script for "
                                f"'{SCENARIO}' changed since the run began); restore the script as the run used it, "
                                "or start a new --out folder")


def test_a_training_resume_on_edited_dv2s_sources_is_refused(tmp_path, monkeypatch):
    Bank().copy_to(tmp_path / "bank")
    out = _training_folder(tmp_path, tmp_path / "bank")
    monkeypatch.setattr(run_identity, "dv2s_sources_sha256", lambda: "f" * 64)
    with pytest.raises(RunIdentityError, match=r"made with other code \(dv2s sources differ: dv2s sources "
                                               r"\(SHA-256\): run has [0-9a-f]{12}, now ffffffffffff\)"):
        _resume_training(out)


# --------------------------------------------------------------------------- dv2s regress
@pytest.mark.slow
def test_a_regression_resume_over_an_edited_script_or_a_changed_plugin_is_refused(tmp_path, plugin):
    bank = tmp_path / "bank"
    Bank().copy_to(bank)
    run = dict(scenarios=[SCENARIO], episodes=1, workers=1, out_dir=tmp_path / "regress", bank_dir=str(bank),
               progress=False, clips=False)
    run_regression("keep_lane", **run)
    run_regression("keep_lane", **run)  # unchanged: resumed
    recorded = json.loads((tmp_path / "regress" / "run.json").read_text(encoding="utf-8"))["settings"]
    assert recorded[CODE_IDENTITY] == code_identity() and recorded[BANK_IDENTITY] == bank_identity(Bank(bank),
                                                                                                   [SCENARIO])
    plugin.write_text(PLUGIN_SOURCE.format(limit=2), encoding="utf-8")
    with pytest.raises(ResumeMismatchError) as error:  # said as every resumable run kind says it
        run_regression("keep_lane", **run)
    assert str(error.value).startswith(f"{tmp_path / 'regress'} holds a regression run made with other code (plug-in "
                                       f"modules' source differ: module {PLUGIN} source (SHA-256): run has ")
    assert str(error.value).endswith("restore the code the run used (dv2s's sources, the plug-in modules DV2S_PLUGINS "
                                     "names, the files they read), or start a new --out folder (its reports (junit.xml, report.html, "
                                     "report.md, report.json) are that run's, not this one's: nothing was written, so "
                                     "do not read them as this run's verdict)")
    plugin.write_text(PLUGIN_SOURCE.format(limit=1), encoding="utf-8")
    script = bank / SCENARIO / "scenario.scenic"
    script.write_text(script.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    with pytest.raises(ResumeMismatchError) as error:
        run_regression("keep_lane", **run)
    assert str(error.value).startswith(f"{tmp_path / 'regress'} holds a regression run over other scenario scripts "
                                       f"(the bank's script for '{SCENARIO}' changed since the run began); restore the "
                                       "script as the run used it, or start a new --out folder")


# --------------------------------------------------------------------------- a DAgger fine-tuning
def test_a_dagger_identity_holds_each_scripts_sha256_as_it_is_on_disk(tmp_path):
    """The bank's own record of a script (its sidecar's ``content_hash``) is not updated by an edit of the script:
    the identity reads the script itself, so an edited script makes another identity."""
    from policies.dagger_checkpoint import run_identity as dagger_identity
    from policies.dagger_config import DaggerConfig
    from policies.registry import SHIPPED_CHECKPOINT

    bank = tmp_path / "bank"
    Bank().copy_to(bank)
    config = TrainConfig(out=str(tmp_path / "ft"), algo="ppo", scenarios=(SCENARIO,), bank_dir=str(bank), steps=100,
                         n_envs=1, eval_freq=0, card_seeds=0, checkpoint_freq=0, progress_bar=False, vec_env="dummy")

    def identity():
        return dagger_identity(source="dv2s-ppo", source_checkpoint=SHIPPED_CHECKPOINT, config=config,
                               dagger=DaggerConfig(), weights={SCENARIO: 1.0}, env_config={})

    before = identity()
    assert before["scenario_hashes"] == bank_identity(Bank(bank), [SCENARIO])
    script = bank / SCENARIO / "scenario.scenic"
    script.write_text(script.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    assert identity()["scenario_hashes"] != before["scenario_hashes"] == {
        SCENARIO: Bank(bank).get(SCENARIO).content_hash}


# --------------------------------------------------------------------------- the mining report
@pytest.mark.parametrize("replaced, said", [
    ([], None),
    (["detector 'collision' (replaced by noop_collision)"],
     "Built-in replaced by plug-ins: detector 'collision' (replaced by noop_collision); what this run counts under "
     "that name is the plug-ins'")])
def test_a_mining_reports_banner_names_the_builtins_plugins_replaced(replaced, said):
    from dv2s_gym.mining.html import render_html
    from dv2s_gym.mining.report import build_report_from_records, format_summary, markdown

    settings = {"policy": "rule", "sampler": "random", "seed": 0, "scenarios": [SCENARIO],
                "code_identity": {"replaced built-ins": replaced}}
    report = build_report_from_records(settings, [], [], {})
    assert report.settings["code_identity"]["replaced built-ins"] == replaced  # report.json's settings
    texts = (format_summary(report), markdown(report), render_html(report).replace("&#x27;", "'"))
    for text in texts:
        assert (said in text) if said else ("replaced by plug-ins" not in text)


def test_the_sources_hash_covers_the_world_models_maps_and_records_but_not_the_evaluation_set(tmp_path, monkeypatch):
    """An edited Scenic world model or map changes how every scenario runs, so it is part of "dv2s sources"."""
    files = {"envs/code.py": "x = 1\n", "envs/scenic_highway/model.scenic": "class Car: pass\n",
             "scenario_bank/maps/town.xodr": "<OpenDRIVE/>\n", "dv2s_gym/loop/untouched/a/meta.json": "{}\n",
             "dv2s_gym/evalset/item.label.json": "{}\n", "policies/checkpoints/p/model_card.json": "{}\n",
             "envs/README.md": "notes\n"}
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    monkeypatch.setattr(run_identity, "_DV2S_ROOT", tmp_path)
    before = run_identity.dv2s_sources_sha256()
    for name in ("dv2s_gym/evalset/item.label.json", "policies/checkpoints/p/model_card.json", "envs/README.md"):
        (tmp_path / name).write_text("edited\n")
        assert run_identity.dv2s_sources_sha256() == before, name
    for name in ("envs/code.py", "envs/scenic_highway/model.scenic", "scenario_bank/maps/town.xodr",
                 "dv2s_gym/loop/untouched/a/meta.json"):
        (tmp_path / name).write_text("edited\n")
        now = run_identity.dv2s_sources_sha256()
        assert now != before, name
        before = now
