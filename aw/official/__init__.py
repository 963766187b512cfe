"""Compatibility with the official AssemblyWorldBench release.

* :mod:`aw.official.package`: an official package's per-sample evaluation inputs (1000 points
  per part in the baked initial geometry, target poses, scale divisor, equivalence groups).
* :mod:`aw.official.archive` / :mod:`aw.official.episode`: 3DWebAgent episode archives
  (``final.episode.zip``), checked member by member before use, states restored to part poses
  with MuJoCo.
* :mod:`aw.official.convert`: both turned into this project's suite + runs layout for
  ``aw-score`` (``suite_geometry`` gives the official-points geometry of a converted task).
"""

from aw.official.archive import ArchiveContents, read_archive
from aw.official.convert import convert, convert_package, suite_eval_inputs, suite_geometry, write_episode_run
from aw.official.episode import Episode, read_episode, restore_poses
from aw.official.package import EvalInputs, OfficialPackage, read_eval_inputs, write_eval_inputs

__all__ = [
    "ArchiveContents",
    "Episode",
    "EvalInputs",
    "OfficialPackage",
    "convert",
    "convert_package",
    "read_archive",
    "read_episode",
    "read_eval_inputs",
    "restore_poses",
    "suite_eval_inputs",
    "suite_geometry",
    "write_episode_run",
    "write_eval_inputs",
]
