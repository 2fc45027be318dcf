"""``dv2s convert`` of several videos: which ones a folder holds, and their conversions in parallel processes."""

from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional, Tuple
from concurrent.futures import ProcessPoolExecutor

from tqdm import tqdm

from dv2s_gym.pipeline.convert import ConversionReport, ConvertSettings, check_conversion_folder, convert_video
from dv2s_gym.pipeline.evaluate import VIDEO_SUFFIXES
from scenario_bank.errors import MissingFileError

__all__ = ["convert_videos", "videos_to_convert"]


def videos_to_convert(source: str | os.PathLike, out: str | os.PathLike) -> List[Tuple[Path, Path]]:
    """The (video, output folder) pairs of a conversion: ``source`` itself, or every video of the folder
    ``source`` (sorted by name, each into ``out/<video stem>``). An ``out`` of a folder's videos that holds a run of
    another kind is refused (:func:`~dv2s_gym.pipeline.convert.check_conversion_folder`)."""
    source = Path(source)
    if not source.is_dir():
        return [(source, Path(out))]
    check_conversion_folder(out)
    videos = sorted(p for p in source.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
    if not videos:
        raise MissingFileError(f"no videos ({', '.join(VIDEO_SUFFIXES)}) in {source}")
    return [(video, Path(out) / video.stem) for video in videos]


def convert_videos(pairs: List[Tuple[Path, Path]], settings: Optional[ConvertSettings] = None, *, jobs: int = 1,
                   progress: bool = True) -> List[ConversionReport]:
    """:func:`convert_video` with ``settings`` for each (video, output folder) pair, in ``jobs`` processes when
    there are several; returns the reports in the order of ``pairs``. An output folder that holds a run of another
    kind is refused before any video is converted (:func:`~dv2s_gym.pipeline.convert.check_conversion_folder`)."""
    for _, out in pairs:
        check_conversion_folder(out)
    reports = []
    with tqdm(total=len(pairs), desc="converting", unit="video", disable=not progress or len(pairs) == 1) as bar:
        if jobs > 1 and len(pairs) > 1:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                futures = [pool.submit(convert_video, str(v), str(o), settings) for v, o in pairs]
                for future in futures:
                    reports.append(future.result())
                    bar.update()
        else:
            for v, o in pairs:
                reports.append(convert_video(str(v), str(o), settings))
                bar.update()
    return reports
