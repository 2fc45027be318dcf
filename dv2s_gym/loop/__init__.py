"""The closed loop: mine the policy's failures, convert them into bank entries, fine-tune, and judge the
fine-tuned policy against a control and the starting policy on held-out and untouched scenarios."""

__all__ = []
