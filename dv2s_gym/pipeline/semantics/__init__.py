"""Semantic elements (the vocabulary of :mod:`scenario_bank.elements`) read from what the pipeline sees.

* :mod:`.text`: from a description's text (the rule-based parser), with its word lists and patterns in
  :mod:`.lexicon` and road features, absences, speeds and distances in :mod:`.road`;
* :mod:`.trace`: from what a simulated episode actually did (its trace).
"""

__all__ = []
