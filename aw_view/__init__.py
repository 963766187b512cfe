"""``aw-view``: a live browser view of recorded episodes, one run or whole batches.

Top-down:

- :mod:`aw_view.cli`: the command (``aw-view PATH [--port P] [--host H] [--suite SUITE]``);
- :mod:`aw_view.server`: the HTTP server (standard library), its pages and JSON API;
- :mod:`aw_view.watch`: what is on disk under PATH: the episodes, their status, their
  recordings read as they grow (:class:`aw.formats.TrajectoryFollower`);
- :mod:`aw_view.public`: the only way the viewer opens a file: the recordings under PATH and
  the public files of tasks (``task.json``, part meshes, reference images);
- :mod:`aw_view.scores`: with ``--suite``, the target as a ghost and each state's PA/SR/SCD,
  computed here through the ``aw_eval`` API and cached.

A package of its own above ``aw`` and ``aw_eval``: the viewer needs the evaluator for scores,
and neither the environment (``aw``, ``aw_server``) nor the evaluator should carry a web server.
Without ``--suite`` it never imports ``aw_eval``, so it starts fast and reads no target.
"""
