"""An episode of a ``dv2s mine`` run re-run from its record (``dv2s replay RUN_FOLDER --episode INDEX``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Optional, Tuple, Union

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.conversion.failure_video import rerun_failure, write_failure_video
from dv2s_gym.mining.miner import read_records
from dv2s_gym.mining.settings import read_run_settings, SETTINGS_FILE
from envs.recording import write_frames
from envs.trace_bounds import check_file_config
from scenario_bank.records import EpisodeRecord, recorded
from policies.registry import spec_from_file

__all__ = ["replay_mined_episode"]

PathLike = Union[str, os.PathLike]


def replay_mined_episode(folder: PathLike, episode: Optional[str], *, policy: Optional[str] = None,
                         video: Optional[PathLike] = None) -> Tuple[EpisodeRecord, str]:
    """Re-run episode ``episode`` (its index) of the ``dv2s mine`` run in ``folder`` with the recorded scenario,
    parameters and seed, checking its trajectory hash (:func:`~dv2s_gym.mining.conversion.failure_video.rerun_failure`);
    with ``video``, also write it (a failure's video with its trace beside it, see
    :func:`~dv2s_gym.mining.conversion.failure_video.write_failure_video`).

    ``policy`` replaces the run's policy spec (needed for one that is not built in: a file's spec is loaded only
    if it is). Returns ``(the episode's record, policy spec)``; a folder that is not a mining run, or an episode that
    did not finish, raises :class:`~dv2s_gym.mining.errors.MiningError` naming the fix.
    """
    folder = Path(folder)
    settings = read_run_settings(folder)
    if settings is None:
        raise MiningError(f"{folder} is not a `dv2s mine` run folder (no {SETTINGS_FILE}); pass a trace file, a "
                         "regress report.json or a mining run folder")
    if episode is None or not str(episode).isdigit():
        raise MiningError(f"{folder} is a mining run: name the episode with --episode INDEX (report.md lists the "
                         "failures and their indices)")
    settings_file = str(settings.path)
    records = {int(r.index): r for r in read_records(folder / "episodes.jsonl")}
    record = records.get(int(episode))
    if record is None or record.error or not recorded(record.result):
        raise MiningError(f"episode {episode} of {folder} did not finish (not in episodes.jsonl, or an error); "
                         f"it has episodes 0..{max(records) if records else -1}")
    if not policy:
        policy = spec_from_file(settings.policy, settings_file, "--policy-spec SPEC")
    options = {"policy": policy, "bank_dir": settings.bank_dir,
               "env_config": check_file_config(settings.env_config, settings_file)}
    if video and record.failure:
        write_failure_video(record, video, trace_path=Path(video).with_suffix(".json.gz"), **options)
    else:
        _, _, frames = rerun_failure(record, render=bool(video), **options)
        if video:
            write_frames(video, frames, options["env_config"].get("policy_frequency", 5))
    return record, policy
