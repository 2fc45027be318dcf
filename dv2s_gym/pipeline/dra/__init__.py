"""Driving Record Analyzer backends: video -> description.

* :mod:`.bev`: ``bev``, the embedded, offline analyzer of bird's-eye renders in highway-env's style;
* :mod:`.openai`: ``openai``, any OpenAI-compatible vision-language model.

:func:`dv2s_gym.pipeline.stages.describe` picks one by name (:func:`~dv2s_gym.pipeline.stages.register_dra`).
"""

__all__ = []
