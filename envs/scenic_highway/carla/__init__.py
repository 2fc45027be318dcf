"""Scenic's CARLA world model on highway-env: ``model.scenic`` (what a script naming
``scenic.simulators.carla.model`` compiles against), its behaviours, the CARLA actions (:mod:`.actions`) and
blueprint sizes and kinds (:mod:`.blueprints`). Nothing here imports ``carla``."""

__all__ = []
