"""``dv2s regress``: compare a candidate driving policy with a baseline on paired episodes."""
