"""The evaluator's speed machinery: compiled nearest-neighbour search (KD-trees, Delaunay walks,
walks in a posed assembly's parts) and ICP from many starts (the certified kernel and ``fast``'s
coarse-to-fine pruning). The protocol modules of :mod:`aw_eval` call these; nothing here decides
what is scored."""
