"""Training, fine-tuning, the loop and the model backends' behaviour, recorded: what they write at a tiny scale.

``tests/data/behaviour/runs.json`` holds, for each part of :data:`PARTS`, SHA-256 digests of what one tiny run
writes:

- ``train``: ``dv2s train`` (PPO, 128 steps, 1 env in this process, seed 0, two bank scenarios, a held-out
  evaluation and a checkpoint every 64 steps, a one-seed model card): the exit status, the standard output, every
  file of the run folder;
- ``dagger``: a DAgger fine-tuning of the shipped ``dv2s-ppo`` (``policies.imitation.dagger_fine_tune``, 200
  labelled steps in 2 iterations of 2 epochs, 1 env, seed 0): every file of its folder;
- ``loop``: ``dv2s loop`` at the smallest settings that still go through the stages of a round (mine 12
  episodes and convert and replay one cluster each, split by family, the held-out episodes of the starting policy,
  the DAgger fine-tuning of both arms, the held-out episodes of both, the regression test, the verdict): the exit
  status, the standard output, every file of the loop folder and every entry the loop added to its working bank.
  The untouched scenario set is left out (``--untouched-seeds 0``): its ``nhtsa_pedestrian__pedestrian_02``
  script samples other parameters from one run to the next with the same seed and scene seed, and even for the
  two episodes of one pair, so what that stage writes is not reproducible and cannot be recorded;
- ``llm``: ``dv2s describe --dra openai`` and ``dv2s convert --dra openai --sg openai`` (a repair round
  included) against the local OpenAI-compatible server of ``tests/llm_server.py``, which answers with recorded
  completions from ``tests/data/llm``: each request body the product sent (its text, and each image it carried
  one digest each), the exit status, the standard output and every file written.

A model (``.zip``: ``model.zip``, each checkpoint) is digested by its members: ``policy.pth`` one digest per
tensor of the state dict (dtype, shape, bytes), the optimizer's state and ``pytorch_variables.pth`` one digest
each, and each field of ``data`` one digest each, but for ``start_time``, the wall times (``t``) of the
episodes in ``ep_info_buffer`` and the readable renderings SB3 writes beside a pickled value (which name memory
addresses): of those, only the pickle and its type are kept; ``system_info.txt`` and ``_stable_baselines3_version`` (the machine and the
installed versions) are not recorded. A TensorBoard event file is digested by its scalars (step, tag, value)
without the ``time/`` ones (``time/fps`` is a speed); its name (a time, the machine, a process id) becomes
``events.out.tfevents``. Every other file goes through ``tests/behaviour_digest.py``, whose docstring lists its
rules, with these further JSON keys dropped (:data:`RUN_VOLATILE_KEYS`): ``wall_time_s`` and ``steps_per_s``
(how long training took), ``seconds_total`` (how long a conversion took) and ``versions`` (the installed packages' versions, which a model card names). The runs
set ``PYTHONHASHSEED=0`` and ``OMP_NUM_THREADS=1``; two runs with the same settings train the same weights on
one CPU (checked before the record was written: torch on CPU with one thread is deterministic here).

``test_several_workers_write_what_one_worker_wrote`` records nothing new: the runs of
``tests/test_behaviour_reports.py`` with ``--workers 2`` must write the digests that file records for one worker,
and so must ``dv2s regress`` on the Ray backend when Ray is installed. The miner's sampler is fed one batch of
outcomes at a time, in the batch's order whatever the workers, so ``dv2s mine`` over several batches draws the
same scenes with 2 workers as with one.

A refactor must leave every digest as it is; a change of behaviour meant to be one changes them, and is recorded
by writing them again (all parts, or the parts named):

    .venv/bin/python tests/test_behaviour_runs.py --write [train] [dagger] [loop] [llm]
"""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Callable, Dict, Mapping

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from behaviour_digest import (differences, digest, file_digests, normalise, normalise_text,  # noqa: E402
                              require_the_jail)

RECORD = ROOT / "tests" / "data" / "behaviour" / "runs.json"
SHIPPED_BANK = ROOT / "scenario_bank" / "scenarios"
RUN_VOLATILE_KEYS = frozenset({"wall_time_s", "steps_per_s", "seconds_total", "versions"})
"""JSON keys dropped from these runs' files beyond the normaliser's: how long training took, installed versions."""

SCENARIOS = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
TRAIN = ["train", "--algo", "ppo", "--scenarios", *SCENARIOS, "--steps", "128", "--envs", "1", "--seed", "0",
         "--vec-env", "dummy", "--hp", "n_steps=64", "--eval-freq", "64", "--eval-seeds", "1", "--card-seeds", "1",
         "--baselines", "keep_lane", "--eval-jobs", "1", "--checkpoint-freq", "64", "--no-progress"]
DAGGER = dict(steps=200, weights={name: 1.0 for name in SCENARIOS}, n_envs=1, vec_env="dummy", iterations=2,
              epochs=2, seed=0, progress_bar=False)
LOOP = ["loop", "--policy", "dv2s-ppo", "--scenarios", "highway_lead_vehicle_brakes", "highway_truck_cut_in",
        "--budget", "12", "--fine-tune-steps", "128", "--k-eval", "1", "--regress-episodes", "1",
        "--min-heldout-episodes", "1", "--min-heldout-families", "1", "--max-conversions", "1",
        "--max-replays", "1", "--untouched-seeds", "0", "--workers", "1", "--envs", "1", "--no-progress"]
CLIP = ROOT / "dv2s_gym" / "evalset" / "highway_lead_vehicle_brakes_seed0.webm"
DESCRIBE = ["describe", str(CLIP), "--dra", "openai", "--camera", "bev", "--json"]
CONVERT = ["convert", str(CLIP), "--dra", "openai", "--sg", "openai", "--camera", "bev", "--seed", "0", "--json"]
CONVERT_ANSWERS = ["dra_lead_vehicle_brakes.json", "sg_lead_brake_attempt1_undefined.json",
                   "sg_lead_brake_attempt2_fixed.json"]
"""The recorded completions served to ``dv2s convert`` in order: the description, a script using a name nothing
defines, its repair."""


def _environment() -> Dict[str, str]:
    environment = {key: value for key, value in os.environ.items() if not key.startswith(("DV2S_", "OPENAI_"))}
    return dict(environment, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", PYTHONHASHSEED="0")


def _stdout(text: str, places: Mapping[str, str]) -> str:
    """The digest of a command's standard output: normalised as JSON when it is JSON (``--json``), else as text."""
    try:
        value = json.loads(text)
    except ValueError:
        return digest(normalise_text(text, places))
    return digest(normalise(value, places, RUN_VOLATILE_KEYS))


def _dv2s(argv: list, work: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dv2s_gym.cli", *argv], cwd=work, env=_environment(),
                          capture_output=True, text=True, timeout=900)


# --------------------------------------------------------------------------- models, event files, folders
def _tensors(value: Any) -> Any:
    """``value`` with every tensor replaced by ``tensor:dtype:shape:SHA-256 of its bytes``."""
    import torch

    if torch.is_tensor(value):
        tensor = value.detach().cpu().contiguous()
        return f"tensor:{tensor.dtype}:{tuple(tensor.shape)}:{digest(tensor.numpy().tobytes())}"
    if isinstance(value, dict):
        return {str(key): _tensors(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_tensors(item) for item in value]
    return value


def _episode_infos(serialized: str) -> Any:
    """The episodes of an SB3 ``ep_info_buffer`` (return and length) without their wall times."""
    import cloudpickle

    return [{key: value for key, value in info.items() if key != "t"}
            for info in cloudpickle.loads(base64.b64decode(serialized))]


def model_digests(path: Path, places: Mapping[str, str]) -> Dict[str, Any]:
    """The digests of a stable-baselines3 model file (see the module docstring)."""
    import torch

    record: Dict[str, Any] = {}
    with zipfile.ZipFile(path) as archive:
        record["members"] = sorted(archive.namelist())
        for member in sorted(archive.namelist()):
            raw = archive.read(member)
            if member.endswith(".pth"):
                state = _tensors(torch.load(io.BytesIO(raw), map_location="cpu", weights_only=False))
                record[member] = ({key: digest(item) for key, item in state.items()}
                                  if member == "policy.pth" else digest(state))
            elif member == "data":
                data = json.loads(raw.decode("utf-8"))
                data.pop("start_time", None)
                data = {key: ({part: item[part] for part in (":type:", ":serialized:") if part in item}
                              if isinstance(item, dict) and ":serialized:" in item else item)
                        for key, item in data.items()}
                if isinstance(data.get("ep_info_buffer"), dict):
                    data["ep_info_buffer"] = _episode_infos(data["ep_info_buffer"][":serialized:"])
                record[member] = {key: digest(item) for key, item in sorted(normalise(data, places).items())}
    return record


def event_digests(path: Path) -> Dict[str, str]:
    """``{tag: digest of its (step, value) list}`` of a TensorBoard event file's scalars, ``time/`` ones left out."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    scalars: Dict[str, list] = {}
    for event in EventFileLoader(str(path)).Load():
        for value in event.summary.value:
            if value.tag.startswith("time/"):
                continue
            number = list(value.tensor.float_val) if value.HasField("tensor") else [value.simple_value]
            scalars.setdefault(value.tag, []).append([event.step, number])
    return {tag: digest(points) for tag, points in sorted(scalars.items())}


def run_digests(folder: Path, places: Mapping[str, str], skip: Callable[[Path], bool] = lambda _: False
                ) -> Dict[str, Any]:
    """``{relative path: digests}`` of every file under ``folder`` (but those ``skip`` names)."""
    record: Dict[str, Any] = {}
    for path in sorted(folder.rglob("*")):
        relative = path.relative_to(folder)
        if not path.is_file() or skip(relative):
            continue
        if path.suffix == ".zip":
            record[str(relative)] = model_digests(path, places)
        elif path.name.startswith("events.out.tfevents."):
            record[str(relative.parent / "events.out.tfevents")] = event_digests(path)
        else:
            record[str(relative)] = file_digests(path, places, RUN_VOLATILE_KEYS)
    return record


# --------------------------------------------------------------------------- the parts
def _train(work: Path) -> Dict[str, Any]:
    out = work / "run"
    done = _dv2s([*TRAIN, "--out", str(out)], work)
    places = {str(out): "<out>", str(ROOT): "<repo>"}
    return {"exit": done.returncode, "stdout": digest(normalise_text(done.stdout, places)),
            "files": run_digests(out, places)}


_DAGGER_SCRIPT = """
import json, sys
sys.path.insert(0, sys.argv[1])
from fine_tune_helpers import dagger_fine_tune
dagger_fine_tune("dv2s-ppo", bank_dir=None, out=sys.argv[2], log=lambda _: None, **json.loads(sys.argv[3]))
"""


def _dagger(work: Path) -> Dict[str, Any]:
    out = work / "dagger"
    done = subprocess.run([sys.executable, "-c", _DAGGER_SCRIPT, str(ROOT / "tests"), str(out), json.dumps(DAGGER)],
                          cwd=work, env=_environment(), capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    return {"files": run_digests(out, {str(out): "<out>", str(ROOT): "<repo>"})}


def _loop(work: Path) -> Dict[str, Any]:
    out = work / "loop"
    done = _dv2s([*LOOP, "--out", str(out)], work)
    places = {str(out / "bank"): "<bank>", str(out): "<out>", str(ROOT): "<repo>"}
    shipped = {entry.name for entry in SHIPPED_BANK.iterdir()}
    bank = out / "bank"
    added = {entry.name: run_digests(entry, places) if entry.is_dir() else file_digests(entry, places)
             for entry in sorted(bank.iterdir()) if entry.name not in shipped} if bank.is_dir() else {}
    return {"exit": done.returncode, "stdout": digest(normalise_text(done.stdout, places)),
            "files": run_digests(out, places, skip=lambda relative: relative.parts[0] == "bank"),
            "bank added": added}


def _request_digests(body: Dict[str, Any]) -> Dict[str, Any]:
    """A chat request's digests: its body with each image replaced by a placeholder, and each image."""
    images = []

    def strip(value: Any) -> Any:
        if isinstance(value, dict):
            if value.get("type") == "image_url":
                images.append(digest(json.dumps(value, sort_keys=True).encode("utf-8")))
                return {"type": "image_url", "image_url": "<image>"}
            return {key: strip(item) for key, item in value.items()}
        if isinstance(value, list):
            return [strip(item) for item in value]
        return value

    text = strip(body)
    return {"text": digest(text), "images": images}


def _llm(work: Path) -> Dict[str, Any]:
    from llm_server import ChatServer

    record = {}
    for name, argv, answers in (("describe", DESCRIBE, ["dra_lead_vehicle_brakes.json"]),
                                ("convert", CONVERT, CONVERT_ANSWERS)):
        out = work / name
        out.mkdir()
        with ChatServer(queue=answers) as server:
            served = ["--base-url", server.base_url, "--model", "gpt-4o", "--api-key", "sk-test"]
            extra = ["--out", str(out / "out")] if name == "convert" else []
            done = _dv2s([*argv, *served, *extra], out)
            requests = [_request_digests(body) for body in server.requests]
        places = {server.base_url: "<server>", str(out): "<out>", str(ROOT): "<repo>"}
        record[name] = {"exit": done.returncode, "stdout": _stdout(done.stdout, places),
                        "requests": requests, "files": run_digests(out, places)}
    return record


PARTS: Dict[str, Callable[[Path], Dict[str, Any]]] = {"train": _train, "dagger": _dagger, "loop": _loop,
                                                       "llm": _llm}


def behaviour(part: str) -> Dict[str, Any]:
    """What the run of ``part`` writes, in a fresh folder."""
    require_the_jail("the recorded runs (the loop's and the conversion's)")
    with tempfile.TemporaryDirectory(prefix=f"dv2s-behaviour-{part}-") as work:
        return PARTS[part](Path(work))


def _check(part: str) -> None:
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))[part]
    now = behaviour(part)
    changed = differences(recorded, now)
    assert not changed, (f"{len(changed)} digest(s) of what `{part}` writes differ: {changed[:12]}; if the change "
                         f"is meant, record it: python tests/test_behaviour_runs.py --write {part}")


@pytest.mark.slow
def test_train_writes_the_model_and_run_folder_it_wrote():
    _check("train")


@pytest.mark.slow
def test_a_dagger_fine_tuning_writes_the_model_and_card_it_wrote():
    _check("dagger")


@pytest.mark.slow
def test_one_round_of_the_loop_writes_what_it_wrote():
    _check("loop")


@pytest.mark.slow
def test_describe_and_convert_send_the_prompts_and_write_the_files_they_did():
    _check("llm")


# --------------------------------------------------------------------------- several workers
def _reports_record() -> Dict[str, Any]:
    return json.loads((ROOT / "tests" / "data" / "behaviour" / "reports.json").read_text(encoding="utf-8"))


def _as_one_worker(out: Path) -> None:
    """Put back what is meant to differ with more workers: the ``workers`` and ``backend`` settings a regression
    report names (in ``report.json`` and its HTML page) become 1 and ``local`` again. (:func:`_same_lines` then
    takes ``results.jsonl``, written in the order the episodes finished, as the same lines in any order.)"""
    report = out / "report.json"
    if report.is_file():
        data = json.loads(report.read_text(encoding="utf-8"))
        if isinstance(data.get("settings"), dict) and "workers" in data["settings"]:
            data["settings"].update(workers=1, backend="local")
            report.write_text(json.dumps(data), encoding="utf-8")
    page = out / "report.html"
    if page.is_file():
        text = page.read_text(encoding="utf-8").replace("<th>workers</th><td>2</td>", "<th>workers</th><td>1</td>")
        page.write_text(text.replace("<th>backend</th><td>ray</td>", "<th>backend</th><td>local</td>"),
                        encoding="utf-8")


def _same_lines(recorded: Dict[str, Any], now: Dict[str, Any]) -> None:
    """Compare the JSON-lines files of two records as multisets: put ``now``'s lines in the record's order when
    they are the same lines."""
    for name, lines in recorded.get("files", {}).items():
        if name.endswith(".jsonl") and isinstance(lines, list) and sorted(lines) == sorted(now["files"].get(name, [])):
            now["files"][name] = list(lines)


def _compare_with_one_worker(run: str, argv: list, label: str, workers: int = 2) -> None:
    import test_behaviour_reports as reports

    require_the_jail("the recorded mining runs")
    with tempfile.TemporaryDirectory(prefix="dv2s-behaviour-workers-") as work:
        now = reports._run(run, argv, Path(work), workers=workers, adjust=_as_one_worker)
    recorded = _reports_record()[run]
    _same_lines(recorded, now)
    changed = differences(recorded, now)
    assert not changed, f"{label} `dv2s {run}` writes other digests than with 1 worker: {changed[:12]}"


@pytest.mark.slow
@pytest.mark.parametrize("run", ["regress", "mine", "mine-convert"])
def test_several_workers_write_what_one_worker_wrote(run):
    import test_behaviour_reports as reports

    _compare_with_one_worker(run, reports.RUNS[run], "with 2 workers")


@pytest.mark.slow
def test_mining_over_several_batches_draws_with_two_workers_what_one_worker_draws():
    """The recorded mining runs fit one batch of the sampler; over three batches (24 episodes, the adaptive sampler
    fed each batch's outcomes before it draws the next) two workers must still draw the same scenes and write the
    same run as one (``episodes.jsonl`` holds its lines in the order episodes ended: compared in index order)."""
    import test_behaviour_reports as reports

    argv = ["mine", "--policy", "keep_lane", "--scenarios", "highway_cut_in_from_left", "urban_pedestrian_crossing",
            "highway_lead_vehicle_brakes", "--budget", "24", "--no-convert"]
    def in_index_order(out: Path) -> None:  # workers finish in their own order; each line is written as one ends
        episodes = out / "episodes.jsonl"
        lines = episodes.read_text(encoding="utf-8").splitlines()
        episodes.write_text("".join(line + "\n" for line in sorted(lines, key=lambda l: json.loads(l)["index"])),
                            encoding="utf-8")

    def as_one_worker(out: Path) -> None:
        _as_one_worker(out)
        in_index_order(out)

    with tempfile.TemporaryDirectory(prefix="dv2s-behaviour-batches-") as work:
        one = reports._run("mine", argv, Path(work) / "one", adjust=in_index_order)
        two = reports._run("mine", argv, Path(work) / "two", workers=2, adjust=as_one_worker)
    changed = differences(one, two)
    assert not changed, f"`dv2s mine` over 3 batches writes other digests with 2 workers: {changed[:12]}"


@pytest.mark.slow
def test_regress_on_ray_writes_what_one_local_worker_wrote(tmp_path, monkeypatch):
    pytest.importorskip("ray")
    import test_behaviour_reports as reports

    # a local Ray instance writes a token to ~/.ray/auth_token, after which connecting to a cluster started by
    # `ray start --head` without one fails (tests/test_regress_ray.py runs such a cluster): keep it out of HOME
    monkeypatch.setenv("HOME", str(tmp_path))

    _compare_with_one_worker("regress", [*reports.RUNS["regress"], "--backend", "ray"], "on Ray")


if __name__ == "__main__" and sys.argv[1:2] == ["--write"]:
    parts = sys.argv[2:] or list(PARTS)
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        sys.exit(f"no such part: {unknown}; the parts are {sorted(PARTS)}")
    record = json.loads(RECORD.read_text(encoding="utf-8")) if RECORD.is_file() else {}
    for part in parts:
        record[part] = behaviour(part)
    RECORD.parent.mkdir(parents=True, exist_ok=True)
    RECORD.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {RECORD} ({', '.join(parts)})")
