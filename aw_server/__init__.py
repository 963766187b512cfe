"""The MCP adapter over :mod:`aw` (``aw-serve``): see :mod:`aw_server.cli` and ``docs/harnesses.md``.

Nothing is imported here, so that ``aw-serve --print-prompt`` and the server start stay cheap.
"""
