"""Command-line entry points of the ``aw`` package (``aw-prepare``)."""
