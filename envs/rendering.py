"""Bird's-eye rendering in highway-env's style, with pedestrians and props.

highway-env draws every lane of the network each frame and knows no
pedestrians. :class:`DV2SViewer` draws only the lanes in view (large maps such
as CARLA's towns hold hundreds) and draws pedestrians as discs and props as
boxes, on top of highway-env's own vehicle graphics.
"""

from __future__ import annotations

import os
from typing import Dict, List, Tuple

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
if "XDG_RUNTIME_DIR" not in os.environ:  # silences SDL's warning on headless machines
    import tempfile

    os.environ["XDG_RUNTIME_DIR"] = tempfile.gettempdir()
if os.environ.get("SDL_VIDEODRIVER") == "dummy":
    # highway-env disables its viewer (black frames) under the dummy driver.
    os.environ["SDL_VIDEODRIVER"] = "offscreen"

import pygame  # noqa: E402
from highway_env.envs.common.graphics import EnvViewer, ObservationGraphics  # noqa: E402
from highway_env.road.graphics import LaneGraphics, WorldSurface  # noqa: E402
from highway_env.vehicle.graphics import VehicleGraphics  # noqa: E402

from envs.scenic_highway.actors import Pedestrian, Prop  # noqa: E402

__all__ = ["DV2SViewer", "PEDESTRIAN_COLOR"]

PEDESTRIAN_COLOR = (255, 140, 0)

_BOXES: Dict[int, Tuple[list, np.ndarray]] = {}


def _lane_boxes(network) -> Tuple[list, np.ndarray]:
    """Lanes of a network with their bounding boxes ``[xmin, ymin, xmax, ymax]`` (cached)."""
    key = id(network)
    if key not in _BOXES:
        lanes, boxes = [], []
        for to_dict in network.graph.values():
            for lane_list in to_dict.values():
                for lane in lane_list:
                    s = np.linspace(0.0, lane.length, max(2, int(lane.length // 5) + 2))
                    pts = np.array([lane.position(si, 0.0) for si in s])
                    pad = lane.width_at(0.0)
                    lanes.append(lane)
                    boxes.append([*(pts.min(axis=0) - pad), *(pts.max(axis=0) + pad)])
        _BOXES[key] = (lanes, np.array(boxes).reshape(-1, 4))
    return _BOXES[key]


class DV2SViewer(EnvViewer):
    """highway-env's viewer, drawing what a Scenic scene holds."""

    def display(self) -> None:
        if not self.enabled:
            return
        surface: WorldSurface = self.sim_surface
        surface.move_display_window_to(self.window_position())
        surface.fill(surface.GREY)
        lanes, boxes = _lane_boxes(self.env.road.network)
        w, h = surface.get_width(), surface.get_height()
        x0, y0 = surface.origin
        x1, y1 = x0 + w / surface.scaling, y0 + h / surface.scaling
        if len(lanes):
            visible = (boxes[:, 2] >= x0) & (boxes[:, 0] <= x1) & (boxes[:, 3] >= y0) & (boxes[:, 1] <= y1)
            for i in np.nonzero(visible)[0]:
                LaneGraphics.display(lanes[i], surface)
        for obj in self.env.road.objects:
            _draw_box(obj, surface)
        if self.env.road.record_history:
            for v in self.env.road.vehicles:
                VehicleGraphics.display_history(v, surface, simulation=self.env.config["simulation_frequency"],
                                                offscreen=self.offscreen)
        for v in self.env.road.vehicles:
            if isinstance(v, Pedestrian):
                _draw_pedestrian(v, surface)
            else:
                VehicleGraphics.display(v, surface, offscreen=self.offscreen)
        ObservationGraphics.display(self.env.observation_type, surface)
        if not self.offscreen:
            self.screen.blit(surface, (0, 0))
            if self.env.config["real_time_rendering"]:
                self.clock.tick(self.env.config["simulation_frequency"])
            pygame.display.flip()


def _draw_pedestrian(p: Pedestrian, surface: WorldSurface) -> None:
    if not surface.is_visible(p.position):
        return
    center = surface.vec2pix(p.position)
    radius = max(3, surface.pix(max(p.LENGTH, p.WIDTH) / 2 + 0.2))
    color = getattr(p, "color", None) or PEDESTRIAN_COLOR
    pygame.draw.circle(surface, color, center, radius)
    pygame.draw.circle(surface, (0, 0, 0), center, radius, 1)


def _draw_box(obj, surface: WorldSurface) -> None:
    if not surface.is_visible(obj.position):
        return
    c, s = np.cos(obj.heading), np.sin(obj.heading)
    half = np.array([[-1, -1], [-1, 1], [1, 1], [1, -1]]) * [obj.LENGTH / 2, obj.WIDTH / 2]
    corners = half @ np.array([[c, s], [-s, c]]) + obj.position
    points: List[Tuple[int, int]] = [surface.vec2pix(pt) for pt in corners]
    color = getattr(obj, "color", None) or (200, 200, 0)
    pygame.draw.polygon(surface, color, points)
    pygame.draw.polygon(surface, (0, 0, 0), points, 1)


_ = Prop
