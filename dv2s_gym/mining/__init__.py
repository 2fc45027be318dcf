"""Closed-loop failure mining: find a policy's failures, turn them into bank scenarios."""
