"""``dv2s convert`` of several videos: which ones a folder holds, and their conversions in parallel processes."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, List, Tuple

from dv2s_gym.pipeline.convert import convert_video
from dv2s_gym.pipeline.evaluate import VIDEO_SUFFIXES

__all__ = ["convert_videos", "videos_to_convert"]


def videos_to_convert(source: str | os.PathLike, out: str | os.PathLike) -> List[Tuple[Path, Path]]:
    """The (video, output folder) pairs of a conversion: ``source`` itself, or every video of the folder
    ``source`` (sorted by name, each into ``out/<video stem>``)."""
    source = Path(source)
    if not source.is_dir():
        return [(source, Path(out))]
    videos = sorted(p for p in source.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
    if not videos:
        raise FileNotFoundError(f"no videos ({', '.join(VIDEO_SUFFIXES)}) in {source}")
    return [(video, Path(out) / video.stem) for video in videos]


def _convert_one(video: str, out: str, options: Dict[str, Any]) -> Dict[str, Any]:
    return convert_video(video, out, **options)


def convert_videos(pairs: List[Tuple[Path, Path]], *, jobs: int = 1, progress: bool = True,
                   **options: Any) -> List[Dict[str, Any]]:
    """:func:`convert_video` for each (video, output folder) pair, in ``jobs`` processes when there are several;
    returns the reports in the order of ``pairs``. ``options`` are :func:`convert_video`'s keyword arguments."""
    from concurrent.futures import ProcessPoolExecutor

    from tqdm import tqdm

    reports = []
    with tqdm(total=len(pairs), desc="converting", unit="video", disable=not progress or len(pairs) == 1) as bar:
        if jobs > 1 and len(pairs) > 1:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                futures = [pool.submit(_convert_one, str(v), str(o), options) for v, o in pairs]
                for future in futures:
                    reports.append(future.result())
                    bar.update()
        else:
            for v, o in pairs:
                reports.append(_convert_one(str(v), str(o), options))
                bar.update()
    return reports
