"""Closed-loop failure mining: sample scenes, run a policy, find and cluster its failures,
turn them into new bank scenarios (``dv2s mine``), and fine-tune on them (``dv2s loop``)."""

__all__ = []
