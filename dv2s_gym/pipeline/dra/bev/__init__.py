"""``bev``: the embedded, offline Driving Record Analyzer for bird's-eye renders.

It reads a video rendered in highway-env's style (flat grey canvas, white lane
lines, the green ego at a fixed spot of the view, other vehicles in any colour
(the project's light-blue cars and purple trucks, stock highway-env's yellow
``LinearVehicle`` and blue ``IDMVehicle``; trucks are told by their size), orange
pedestrian discs, grey props with black outlines, crashed vehicles in red; the
camera follows the ego, north up; any ``scaling`` and screen size) and returns what the
Driving Record Analyzer returns: a three-sentence description and the semantic
elements of :mod:`scenario_bank.elements`. It works from the pixels alone: no
trace, sidecar or metadata is read.

How, per clip (one module of this package per step: :mod:`.frames`, :mod:`.detection`,
:mod:`.tracking`, :mod:`.road`, :mod:`.events`, :mod:`.language`; :mod:`.analyze` runs them):

1. *Check* that the frames look like such a render, else :class:`NotBirdsEyeError`.
2. *Detect*, per frame: coloured blobs (every hue; the colour class marks the ego,
   pedestrians and crashed vehicles), props by their black outline, white lane-line
   pixels split into horizontal, vertical and other (ramps, arcs) lines.
3. *Calibrate* the scale (px/m) from the common vehicles in view (:mod:`.scale`;
   the lane lines' spacing is measured beside it); the ego's heading is its
   long axis, pointed by its lighter front end (headlights) or by the world's motion.
4. *Track* the blobs in the ego-centred view (nearest neighbour, constant relative velocity).
5. *World motion*: the static layer (lane lines, props, waiting pedestrians)
   moves opposite to the ego. Its shift between frames comes from correlating
   the line masks; the ambiguity of periodic stripes is resolved by a Viterbi
   pass favouring a smooth ego speed, agreement with static anchors and
   vehicles that do not drive backwards. Ego velocity plus relative motion gives
   every actor's absolute velocity.
6. *Road*: lane-line orientation, count and pattern: parallel one-way lanes
   (highway), 1+1 lanes (straight road), a + or a T of perpendicular roads,
   a ramp joining (merge), arcs (roundabout).
7. *Events* in the ego's driving frame: brake, stop, accelerate, lane changes,
   cut-in, merge, overtake, turns, crossing, collisions, drift; relations where
   each actor starts. Actors that interact with the ego are described in full;
   the other vehicles in view are only counted.

The description is written so that :func:`dv2s_gym.pipeline.semantics.text.elements_from_text`
reads the same elements back from it.

Use :func:`analyze_bev_file` on a path or :func:`analyze_bev` on a
:class:`~dv2s_gym.pipeline.video.VideoClip`. World motion is measured between
consecutive frames, so the analyzer wants 5 frames/s or more; a sparser clip
that names a readable file is re-read at :data:`BEV_READ_OPTIONS` (same pixels,
denser in time).
"""

from dv2s_gym.pipeline.dra.bev.analyze import BevAnalysis, analyze_bev, analyze_bev_file
from dv2s_gym.pipeline.dra.bev.frames import BEV_READ_OPTIONS, NotBirdsEyeError

__all__ = ["BevAnalysis", "NotBirdsEyeError", "analyze_bev", "analyze_bev_file", "BEV_READ_OPTIONS"]
