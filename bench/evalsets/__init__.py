"""Builders of the labeled evaluation sets: the in-house one shipped in ``dv2s_gym/evalset/`` (``dv2s eval --set
in-house``) and the external one kept beside its builder in ``highway_env/``.

* :mod:`.make_evalset`: the in-house set, bird's-eye clips of bank scenarios rendered with :mod:`.make_bev_clips`;
* :mod:`.make_external_evalset`: clips of stock highway-env, scripted and labelled by hand.
"""
