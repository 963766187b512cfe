"""Reading and writing the official AssemblyWorld benchmark's artefacts.

* :mod:`aw.official.archive`: episode archives (``*.episode.zip``), checked member by member
  (names, sizes, hash inventory, records) and written in the same layout;
* :mod:`aw.official.episode`: their worlds (MJCF or MJB) and states restored with MuJoCo 3.12.0;
* :mod:`aw.official.world`: setup archives made from part meshes, and new states;
* :mod:`aw.official.evaluation_cache`: the per-sample ``evaluation.json`` (points, target poses,
  scale divisor, equivalence groups);
* :mod:`aw.official.package`: the benchmark package (``benchmark.json``, block ``config.json``,
  reference pages);
* :mod:`aw.official.convert` / :mod:`aw.official.export`: official artefacts to this project's
  suite and runs, and recorded runs back to official episode archives;
* :mod:`aw.official.ids`: sample ids and their folder names; :mod:`aw.official.errors`: the
  named errors.
* :mod:`aw.official.runlog`: the runner's run-log tree (``logs/<run>/...``), resumed chains
  merged as the official evaluation merges them, and the tree written;
  :mod:`aw.official.runlog_export`: runs recorded here written as one run log;
* :mod:`aw.official.evaluation_output`: ``metrics.jsonl`` and ``summary.json`` read, computed
  from rows by the official rules, written and compared.

The formats are described in ``docs/formats.md``.
"""

from aw.official.eval_points import suite_eval_inputs

__all__ = ["suite_eval_inputs"]
