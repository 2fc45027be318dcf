"""Scenario Generator backends: description -> Scenic script.

* :mod:`.rules`: ``rules``, the embedded, offline composer, from the building blocks of :mod:`.blocks`;
* :mod:`.openai`: ``openai``, any OpenAI-compatible LLM with the fixed context and compile-in-the-loop repair.

:func:`dv2s_gym.pipeline.stages.generate` picks one by name (:func:`~dv2s_gym.pipeline.stages.register_sg`).
"""

__all__ = []
