"""Scenic's MetaDrive world model on highway-env: ``model.scenic``, what a script naming
``scenic.simulators.metadrive.model`` compiles against."""

__all__ = []
