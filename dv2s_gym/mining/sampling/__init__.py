"""How the miner chooses the next scene to run: the samplers, the parameter space and its grid, the
rare-event rate estimate, and the authenticated sampler checkpoints."""

__all__ = []
