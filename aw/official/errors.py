"""Named errors for official artefacts. Each one is an :class:`aw.formats.FormatError`, so its
message names the file (and the member or key) and callers that catch ``FormatError`` keep
working; the subclass says which kind of problem it is, so tests and tools can tell them apart.
"""

from __future__ import annotations

from aw.formats import FormatError

__all__ = [
    "OfficialFormatError",
    "NotAnArchiveError",
    "UnsafeMemberError",
    "ArchiveTooLargeError",
    "HashInventoryError",
    "UnsupportedEpisodeError",
    "InconsistentEpisodeError",
    "EngineVersionError",
    "WorldModelError",
    "EpisodeMismatchError",
    "EvaluationCacheError",
    "PackageError",
    "MissingPackageFileError",
    "SampleIdError",
    "ExportError",
]


class OfficialFormatError(FormatError):
    """Base class: an official artefact that cannot be used as it is."""


class NotAnArchiveError(OfficialFormatError):
    """The file is missing or is not a readable zip archive."""


class UnsafeMemberError(OfficialFormatError):
    """A member name could escape the archive (absolute, ``..``, backslash, drive, control
    characters), appears twice, or is a link or other special file."""


class ArchiveTooLargeError(OfficialFormatError):
    """A member or the whole archive inflates past the reader's limits (zip bombs included)."""


class HashInventoryError(OfficialFormatError):
    """``manifest.hashes`` does not list exactly the archive's members, or a digest differs."""


class UnsupportedEpisodeError(OfficialFormatError):
    """Another episode format, version, engine or contract than the official one."""


class InconsistentEpisodeError(OfficialFormatError):
    """The records contradict each other or the episode contract (frames, calls, events,
    lifecycle, keys and types)."""


class EngineVersionError(OfficialFormatError):
    """The installed MuJoCo is not the version the official worlds are made for."""


class WorldModelError(OfficialFormatError):
    """The archive's world (MJCF XML with its assets, or compiled MJB) cannot be loaded, or
    lacks the part bodies."""


class EpisodeMismatchError(OfficialFormatError):
    """A final archive is not a continuation of its initial archive (catalogue, identity,
    world or state layout differ), or the parts differ from the evaluation inputs."""


class EvaluationCacheError(OfficialFormatError):
    """An ``evaluation.json`` is malformed or belongs to another sample or protocol."""


class PackageError(OfficialFormatError):
    """A benchmark package file (``benchmark.json``, ``config.json``, ``pages.json``) is
    missing, malformed or inconsistent with the rest of the package."""


class MissingPackageFileError(PackageError):
    """A file the package lists is not there (a partly downloaded package)."""


class SampleIdError(OfficialFormatError):
    """A sample id or sample folder name that the official runner would refuse."""


class ExportError(OfficialFormatError):
    """A project run cannot be written as an official episode archive."""
