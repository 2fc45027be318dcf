"""The clip's scale (pixels per metre), estimated from what is in the frame.

highway-env draws every vehicle as its rectangle (body colour inside a 1-px dark outline), and its
common vehicles are 2 m wide and 4.5 m (the project's bank) to 5 m (highway-env's own envs) long. The
scale is taken from the body size of those common vehicles (the ego and every car-shaped vehicle seen
whole, long vehicles left out), length and width averaged so that the 4.5/5 m ambiguity costs at most
about 5 %; the spacing of parallel lane lines is measured beside it (``lane_px``) as a check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from dv2s_gym.pipeline.dra.bev.frames import NotBirdsEyeError

COMMON_LENGTH_M = 4.5        # the coloured body of the common cars, calibrated on the bank's renders (see above)
COMMON_WIDTH_M = 2.0
OUTLINE_PX = 2.0             # the 1-px outline on both sides, not part of the coloured body
LONG_RATIO = 1.6             # a vehicle this many common lengths long is a truck (or a bus)
LANE_WIDTH_M = 4.0           # highway-env's lane width (StraightLane.DEFAULT_WIDTH)
LANE_RULER_M = LANE_WIDTH_M

__all__ = ["lane_width_scale", "LANE_RULER_M", "ScaleEstimate", "body_scale", "estimate_scale", "is_long_vehicle", "COMMON_LENGTH_M",
           "LONG_RATIO"]


def body_scale(length_px: float, width_px: float) -> float:
    """Pixels per metre that a common vehicle's coloured body of this size implies."""
    return 0.5 * ((length_px + OUTLINE_PX) / COMMON_LENGTH_M + (width_px + OUTLINE_PX) / COMMON_WIDTH_M)


def is_long_vehicle(length_px: float, common_length_px: float) -> bool:
    """A truck or bus by its size: at least :data:`LONG_RATIO` common vehicle lengths (hue plays no part)."""
    return common_length_px > 0 and length_px >= LONG_RATIO * common_length_px


@dataclass
class ScaleEstimate:
    """The scale and what it was measured from."""

    px_per_m: float
    common_length_px: float          # body length of the common vehicles (px)
    common_width_px: float
    samples: int                     # vehicle views used
    lane_px: Optional[float] = None  # median spacing of adjacent parallel lane lines (px), when seen
    evidence: Dict[str, float] = field(default_factory=dict)

    def as_debug(self) -> Dict[str, float]:
        out = {"px_per_m": round(self.px_per_m, 3), "common_length_px": round(self.common_length_px, 2),
               "common_width_px": round(self.common_width_px, 2), "vehicle_views": self.samples}
        if self.lane_px is not None:
            out["lane_px"] = round(self.lane_px, 2)
            out["lane_px_per_m"] = round(self.lane_px / LANE_WIDTH_M, 3)
        return out


def _car_shaped(length: float, width: float) -> bool:
    return width >= 2.0 and 1.7 * width <= length + OUTLINE_PX <= 3.4 * (width + OUTLINE_PX)


def estimate_scale(ego_sizes: Sequence[Tuple[float, float]], other_sizes: Iterable[Tuple[float, float]] = (),
                   line_positions: Iterable[Sequence[float]] = ()) -> ScaleEstimate:
    """Scale from the body sizes (length, width in px) of the ego (every frame) and of other whole
    vehicles; ``line_positions``: per frame, the sorted positions (px) of the lane lines of one family.

    The ego's views come first; the other vehicles count only when car-shaped and within 25 % of the
    ego's length (long vehicles, pedestrians and partly seen vehicles stay out). Raises NotBirdsEyeError (a
    ValueError) when no ego size is given."""
    ego = [(l, w) for l, w in ego_sizes if l > 0 and w > 0]
    if not ego:
        raise NotBirdsEyeError("no ego vehicle size to estimate the scale from")
    ego_len = float(np.median([l for l, _ in ego]))
    views: List[Tuple[float, float]] = list(ego)
    for l, w in other_sizes:
        if _car_shaped(l, w) and abs(l - ego_len) <= 0.25 * ego_len:
            views.append((l, w))
    length = float(np.median([l for l, _ in views]))
    width = float(np.median([w for _, w in views]))
    scale = max(1.0, body_scale(length, width))
    gaps: List[float] = []
    for pos in line_positions:
        p = np.sort(np.asarray(pos, float))
        d = np.diff(p)
        gaps.extend(x for x in d.tolist() if 0.5 * LANE_WIDTH_M * scale < x < 2.0 * LANE_WIDTH_M * scale)
    lane_px = float(np.median(gaps)) if gaps else None
    return ScaleEstimate(scale, length, width, len(views), lane_px)


def lane_width_scale(frames, body_px_per_m: float, min_gaps: int = 10) -> Optional[float]:
    """Pixels per metre from the spacing of adjacent parallel lane lines (highway-env lanes are
    :data:`LANE_WIDTH_M` wide); None when too few spacings agree with the vehicles' scale
    (``body_px_per_m``, within 0.6x to 1.25x)."""
    gaps: List[float] = []
    lo, hi = 0.6 * LANE_WIDTH_M * body_px_per_m, 1.25 * LANE_WIDTH_M * body_px_per_m
    for fr in frames:
        for pos in (fr.lines.h_pos, fr.lines.v_pos):
            if len(pos) >= 2:
                d = np.diff(np.sort(np.asarray(pos, float)))
                gaps.extend(x for x in d.tolist() if lo <= x <= hi)
    if len(gaps) < min_gaps:
        return None
    return float(np.median(gaps)) / LANE_WIDTH_M
