"""The common row schema of the official re-hosted datasets, read from Parquet or Arrow files.

One row is one object. Columns (names as published; alternatives in brackets)::

    object_id [sample_id, id, uid, name]  string (or integer) id of the object
    source [dataset]                optional: partnet, ikea_manual, assemblybench, fantastic_breaks, ...
    category                        optional string; without it, the part of an id like
                                    ``Bench/applaro`` before the slash (the official ids)
    parts                           list of {part_id, vertices, faces}:
        part_id                     string or integer
        vertices                    list of [x, y, z] (or a flat list of 3n numbers)
        faces                       list of polygons: vertex index lists of 3 or more, triangulated here
    parts_ct                        number of parts (checked against ``parts``)
    geometric_equivalence_relation  optional list of lists of part ids
    manual_pages                    optional list of {page, step, image}; image is encoded bytes
                                    or {bytes, path} (the Hugging Face image struct)
    up_axis                         optional "y" or "z"
    poses, steps                    AssemblyBench: ``poses["0"][<last step_id>][part_id]`` is the
                                    assembled pose [tx, ty, tz, qw, qx, qy, qz] of a part whose
                                    vertices are local (the official adapter's reading)

A download holds one or more ``*.parquet`` files (or ``*.arrow`` IPC files, file or stream
format); rows are addressed as ``(file, row index)``. PartNet and IKEA-Manual rows are taken as
Y-up (their published frames) unless ``up_axis`` says otherwise; other sources as Z-up.

Each object keeps in ``meta["official"]`` what the official preparation protocol needs to
reproduce the official numbers (:mod:`aw.prepare.official_task`): the sample id, the turn to
Z up, the polygon faces as published, and the local vertices and poses of posed parts.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import trimesh

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.sources.meshdata import mesh_from_arrays, natural_key

__all__ = [
    "ID_COLUMNS",
    "SOURCE_ALIASES",
    "data_files",
    "read_table",
    "read_row",
    "load_row",
    "catalog",
    "normalize_source",
]

ID_COLUMNS = ("object_id", "sample_id", "id", "uid", "name")
SOURCE_COLUMNS = ("source", "dataset")
SOURCE_ALIASES = {
    "partnet": "partnet",
    "ikea_manual": "ikea_manual",
    "ikea": "ikea_manual",
    "ikeamanual": "ikea_manual",
    "assemblybench": "assemblybench",
    "assembly_bench": "assemblybench",
    "fantastic_breaks": "fantastic_breaks",
    "fantasticbreaks": "fantastic_breaks",
    "breaking_bad": "breaking_bad",
    "breakingbad": "breaking_bad",
}
Y_UP_SOURCES = ("partnet", "ikea_manual")


def normalize_source(name: str) -> str:
    key = str(name).strip().lower().replace("-", "_").replace(" ", "_")
    return SOURCE_ALIASES.get(key, key)


def data_files(path: str | Path) -> list[Path]:
    """The Parquet/Arrow files of a download: ``path`` itself, or every such file below it."""
    path = Path(path)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise FormatError(path, "not found")
    files = [p for p in path.rglob("*") if p.is_file() and p.suffix in (".parquet", ".arrow")]
    if not files:
        raise FormatError(path, "no .parquet or .arrow files")
    return sorted(files, key=lambda p: natural_key(p.relative_to(path).as_posix()))


def read_table(path: str | Path, columns: list[str] | None = None) -> pa.Table:
    """A whole Parquet or Arrow (IPC file or stream) file, or the named columns of it."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file not found")
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            if columns is not None:
                have = set(pq.read_schema(path).names)
                columns = [c for c in columns if c in have]
            return pq.read_table(path, columns=columns)
        with pa.memory_map(str(path)) as src:
            try:
                table = pa.ipc.open_file(src).read_all()
            except pa.ArrowInvalid:
                src.seek(0)
                table = pa.ipc.open_stream(src).read_all()
        if columns is not None:
            table = table.select([c for c in columns if c in table.column_names])
        return table
    except FormatError:
        raise
    except (pa.ArrowException, OSError) as exc:
        raise FormatError(path, f"cannot be read as Parquet/Arrow ({type(exc).__name__}: {exc})") from None


def read_row(path: str | Path, row: int) -> tuple[dict[str, Any], list[str]]:
    """Row ``row`` of a file as a dict, and the file's column names; reads only the Parquet row
    group (or Arrow record batch) holding it."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file not found")
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            pf = pq.ParquetFile(path)
            total, start = pf.metadata.num_rows, 0
            if 0 <= row < total:
                for g in range(pf.num_row_groups):
                    n = pf.metadata.row_group(g).num_rows
                    if row < start + n:
                        table = pf.read_row_group(g)
                        return table.slice(row - start, 1).to_pylist()[0], table.column_names
                    start += n
        else:
            table = read_table(path)
            total = table.num_rows
            if 0 <= row < total:
                return table.slice(row, 1).to_pylist()[0], table.column_names
    except FormatError:
        raise
    except (pa.ArrowException, OSError) as exc:
        raise FormatError(path, f"cannot be read as Parquet/Arrow ({type(exc).__name__}: {exc})") from None
    raise FormatError(path, f"row {row}: out of range (the file has {total} rows)")


def _column(names: list[str], options: tuple[str, ...]) -> str | None:
    return next((c for c in options if c in names), None)


def _image(value: Any, where: Path, field: str):
    from PIL import Image

    data = value.get("bytes") if isinstance(value, dict) else value
    if not isinstance(data, (bytes, bytearray)) or not data:
        raise FormatError(where, f"{field}: no encoded image bytes")
    try:
        im = Image.open(io.BytesIO(data))
        im.load()
    except Exception as exc:  # PIL raises many types for broken data
        raise FormatError(where, f"{field}: cannot be decoded as an image ({type(exc).__name__})") from None
    return im


def _int(value: Any, where: Path, field: str) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or (isinstance(value, float) and not value.is_integer())
    ):
        raise FormatError(where, f"{field}: expected an integer, got {value!r}")
    return int(value)


def load_row(path: str | Path, row: int, source: str | None = None, up_axis: str | None = None) -> AssembledObject:
    """Row ``row`` of the file ``path`` as an assembled object.

    ``source`` overrides the row's source column; ``up_axis`` overrides the source default
    (the row's ``up_axis`` column, if any, wins over both).
    """
    path = Path(path)
    rec, names = read_row(path, row)
    where = f"row {row}"
    id_col = _column(names, ID_COLUMNS)
    if id_col is None or rec[id_col] in (None, ""):
        raise FormatError(path, f"{where}: no object id column (one of {ID_COLUMNS})")
    object_id = str(rec[id_col])
    src_col = _column(names, SOURCE_COLUMNS)
    src = normalize_source(source or (rec[src_col] if src_col and rec[src_col] else "") or "rehosted")
    parts_raw = rec.get("parts")
    if not isinstance(parts_raw, list) or not parts_raw:
        raise FormatError(path, f"{where}.parts: missing or empty")
    up = rec.get("up_axis") or up_axis or ("y" if src in Y_UP_SOURCES else "z")
    if up not in ("y", "z"):
        raise FormatError(path, f"{where}.up_axis: expected 'y' or 'z', got {up!r}")
    posed = _final_poses(rec, path, where)
    official: dict[str, Any] = {"sample_id": object_id, "faces": {}, "local": {}, "poses": {}}
    if up == "y":
        official["source_to_z_up"] = Y_TO_Z_UP.tolist()
    parts = []
    for k, p in enumerate(parts_raw):
        field = f"{where}.parts[{k}]"
        if not isinstance(p, dict):
            raise FormatError(path, f"{field}: expected a struct with part_id, vertices, faces")
        pid = p.get("part_id")
        if pid is None or str(pid) == "":
            raise FormatError(path, f"{field}.part_id: missing")
        pid = str(pid)
        mesh = mesh_from_arrays(p.get("vertices"), p.get("faces"), path, field, polygons=True)
        if any(len(f) != 3 for f in p["faces"]):
            official["faces"][pid] = [[int(i) for i in f] for f in p["faces"]]
        if posed is not None:
            if pid not in posed:
                raise FormatError(path, f"{field}: no assembled pose for part {pid!r} in poses")
            official["local"][pid], official["poses"][pid] = np.asarray(mesh.vertices), posed[pid]
            mesh = _posed(mesh, posed[pid])
        parts.append(SourcePart(pid, y_up_to_z_up(mesh) if up == "y" else mesh))
    ids = [p.name for p in parts]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise FormatError(path, f"{where}.parts: duplicate part_id {dup}")
    if rec.get("parts_ct") is not None:
        n = _int(rec["parts_ct"], path, f"{where}.parts_ct")
        if n != len(parts):
            raise FormatError(path, f"{where}.parts_ct: says {n} but the row has {len(parts)} parts")

    equivalence = None
    rel = rec.get("geometric_equivalence_relation")
    if rel:
        groups = []
        for g, group in enumerate(rel):
            members = [str(x) for x in (group or [])]
            bad = [m for m in members if m not in ids]
            if bad:
                raise FormatError(path, f"{where}.geometric_equivalence_relation[{g}]: unknown part ids {bad}")
            members = list(dict.fromkeys(members))
            if len(members) > 1:
                groups.append(members)
        equivalence = groups or None

    references: dict[str, list[Any]] = {}
    meta: dict[str, Any] = {"file": str(path), "row": row, "up_axis": up, "official": official}
    pages = rec.get("manual_pages") or []
    if pages:
        found = []
        for k, pg in enumerate(pages):
            field = f"{where}.manual_pages[{k}]"
            if not isinstance(pg, dict):
                raise FormatError(path, f"{field}: expected a struct with page, step, image")
            if pg.get("kind", "diagram") != "diagram" or str(pg.get("view_id", 0)) != "0":
                continue  # AssemblyBench: one ordinary diagram of view 0 per step
            # Without a page number the published order stands (the official rows: IKEA pages
            # carry manual_id/page_index, AssemblyBench pages step_id).
            page = _int(pg["page"], path, f"{field}.page") if "page" in pg else k
            raw_step = pg.get("step", pg.get("step_id"))
            step = _int(raw_step, path, f"{field}.step") if raw_step is not None else None
            found.append((page, -1 if step is None else step, _image(pg.get("image"), path, f"{field}.image")))
        found.sort(key=lambda t: (t[0], t[1]))
        if found:
            references["manual"] = [im for _, _, im in found]
            references["image"] = [found[-1][2]]  # the final page shows the finished object
            meta["manual_pages"] = [{"page": p, "step": s if s >= 0 else None} for p, s, _ in found]
    return AssembledObject(
        object_id=object_id,
        source=src,
        dataset=f"rehosted:{src}",
        category=category_of(rec.get("category"), object_id),
        parts=parts,
        references=references,
        equivalence=equivalence,
        meta=meta,
    )


Y_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # (x, y, z) -> (x, -z, y)


def category_of(category: Any, object_id: str) -> str:
    """The row's category in lower case; without one, the prefix of an id ``<Category>/<name>``."""
    if category:
        return str(category).lower()
    head, sep, _ = str(object_id).partition("/")
    return head.lower() if sep else ""


def _final_poses(rec: dict[str, Any], path: Path, where: str) -> dict[str, list[float]] | None:
    """AssemblyBench's assembled poses: view ``"0"`` at the last step, or None without ``poses``."""
    views = rec.get("poses")
    if not views:
        return None
    steps = rec.get("steps") or []
    try:
        last = str(max(int(s["step_id"]) for s in steps))
        chosen = views["0"][last]
        return {str(k): [float(x) for x in v] for k, v in chosen.items() if v is not None and len(v) == 7}
    except (KeyError, TypeError, ValueError):
        raise FormatError(
            path, f'{where}.poses: expected view "0" with a 7-number pose per part at the last step of steps'
        ) from None


def _posed(mesh: trimesh.Trimesh, pose: list[float]) -> trimesh.Trimesh:
    """``mesh`` moved by ``pose`` ``[tx, ty, tz, qw, qx, qy, qz]``."""
    from aw.pose import apply_pose

    return trimesh.Trimesh(
        apply_pose(np.asarray(pose), np.asarray(mesh.vertices)), np.asarray(mesh.faces), process=False
    )


# The official re-hosted repositories (assembly_world_agent/adapters/*.py, REPO_ID): a download
# whose path names one of them holds that source's rows (the rows themselves name no source).
REPOSITORIES = {
    "partnet-manualpa": "partnet",
    "ikea-manual": "ikea_manual",
    "assemblybench": "assemblybench",
    "fantastic-breaks": "fantastic_breaks",
    "breaking-bad-volume-constrained": "breaking_bad",
}


def source_of_download(path: str | Path) -> str | None:
    """The source a download's path names by its official repository: a folder ``ikea-manual``
    or a Hugging Face cache entry ``datasets--AssemblyWorld--ikea-manual``."""
    for part in reversed(Path(path).resolve().parts):
        name = part.lower().replace("_", "-")
        for repo, src in REPOSITORIES.items():
            if name == repo or name.endswith("--" + repo):  # a folder, or a Hugging Face cache entry
                return src
    return None


def catalog(path: str | Path, source: str | None = None):
    """Every row of a download as :class:`aw.sources.compose.CatalogEntry` records, grouped by
    nothing: callers split them by ``entry.source``. Only the small columns are read (plus
    ``parts`` when a file has no ``parts_ct``). A row's source: ``source``, else its source
    column, else the official repository its path names (:func:`source_of_download`)."""
    from aw.sources.compose import CatalogEntry

    out = []
    source = source or None
    for f in data_files(path):
        small = read_table(f, [*ID_COLUMNS, *SOURCE_COLUMNS, "category", "parts_ct"])
        names = small.column_names
        id_col = _column(names, ID_COLUMNS)
        if id_col is None:
            raise FormatError(f, f"no object id column (one of {ID_COLUMNS})")
        counts = (
            small.column("parts_ct").to_pylist()
            if "parts_ct" in names
            else [len(p or []) for p in read_table(f, ["parts"]).column("parts").to_pylist()]
        )
        src_col = _column(names, SOURCE_COLUMNS)
        srcs = small.column(src_col).to_pylist() if src_col else [None] * small.num_rows
        cats = small.column("category").to_pylist() if "category" in names else [None] * small.num_rows
        for row, (oid, n, s, c) in enumerate(zip(small.column(id_col).to_pylist(), counts, srcs, cats, strict=True)):
            n = _int(n, f, f"row {row}.parts_ct")
            named = source or s or source_of_download(f)
            src = normalize_source(named or "rehosted")
            args = (str(f), row) + ((src,) if named else ())
            out.append(CatalogEntry(src, str(oid), category_of(c, str(oid)), n, "aw.sources.rehosted:load_row", args))
    return out
