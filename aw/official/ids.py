"""Official sample ids and the folder names made from them.

A sample id is one or more ``/``-separated components of ``[A-Za-z0-9_.-]`` characters, none of
them ``.`` or ``..``; its folder name (slug) replaces every ``/`` with ``--``: ``Chair/reidar``
becomes ``Chair--reidar`` (assembly-world-bench ``common.py``, ``sample_name``). Slugs name the
package's ``cache/<slug>/`` folders and the run log's ``samples/<slug>/`` folders; every JSON
file holds the id itself.
"""

from __future__ import annotations

import re

from aw.official.errors import SampleIdError

__all__ = ["SLUG_SEPARATOR", "check_sample_id", "sample_slug", "sample_id_from_slug", "task_id_for_sample"]

SLUG_SEPARATOR = "--"
_COMPONENT = re.compile(r"[A-Za-z0-9_.-]+")


def check_sample_id(sample_id: object, where: str = "<sample id>") -> str:
    """``sample_id`` when the official runner accepts it; :class:`SampleIdError` otherwise."""
    if not isinstance(sample_id, str) or not sample_id:
        raise SampleIdError(where, f"sample id must be a non-empty string, got {sample_id!r}")
    for part in sample_id.split("/"):
        if not _COMPONENT.fullmatch(part) or part in (".", ".."):
            raise SampleIdError(
                where, f"unsafe sample id {sample_id!r}: component {part!r} is not [A-Za-z0-9_.-]+ (nor . or ..)"
            )
    return sample_id


def sample_slug(sample_id: str, where: str = "<sample id>") -> str:
    """The folder name of a sample: ``Chair/reidar`` -> ``Chair--reidar``."""
    return check_sample_id(sample_id, where).replace("/", SLUG_SEPARATOR)


def sample_id_from_slug(slug: str, where: str = "<sample folder>") -> str:
    """The sample id a folder name stands for: ``Chair--reidar`` -> ``Chair/reidar``.

    The official mapping is one-way (an id component may itself contain ``--``), so the files
    that hold the id (``input.json``, ``evaluation.json``) decide whenever they are at hand."""
    return check_sample_id(slug.replace(SLUG_SEPARATOR, "/"), where)


def task_id_for_sample(block: str, sample_id: str) -> str:
    """This project's task id for an official sample: ``<block>--<slug>``.

    The block is part of the id because the two PartNet blocks hold the same sample ids."""
    if not _COMPONENT.fullmatch(block or ""):
        raise SampleIdError("<block>", f"block name {block!r} is not [A-Za-z0-9_.-]+")
    return f"{block}{SLUG_SEPARATOR}{sample_slug(sample_id)}"
