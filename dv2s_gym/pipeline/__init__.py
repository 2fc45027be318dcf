"""The D-V2S pipeline: video input, Driving Record Analyzer, Scenario Generator, semantics and metrics."""

__all__ = []
