"""A mined failure into bank entries: its video converted by D-V2S and judged against the failure, and
its exact replay (the parent scenario narrowed around the failing scene)."""

__all__ = []
