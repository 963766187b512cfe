"""Dataset sources: each turns published objects into :class:`aw.assembly.AssembledObject`.

``aw.sources.synthetic``: the embedded procedural benchmark; ``aw.sources.folder``: a folder of
one's own assembled objects. Loaders for the paper's datasets live in sibling modules.
"""
