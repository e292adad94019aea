"""Writing behavioural files into a BIDS dataset that already exists, touching nothing else.

A lab's dataset may hold EEG, MRI, other studies' subjects and participant columns of
its own (``age``, ``sex``). :func:`merge_into_dataset` adds or replaces only what
vibrofocus wrote:

- a manifest, ``DIR/.vibrofocus-bids.json`` (a dotfile: BIDS tools ignore it), lists each
  file vibrofocus wrote with the SHA-256 of its bytes and the source it was exported
  from. A file at a path vibrofocus would write is replaced only if the manifest lists
  it with its current hash and the same source (an earlier export of the same study,
  unedited); any other file there (a lab's own, an edited one, another study's
  participant of the same label, an export of a vibrofocus without the manifest) is a
  conflict: nothing is written unless ``force``;
- ``participants.tsv`` is merged: its header and every row are kept, cell for cell;
  vibrofocus's columns are added where missing (``n/a`` in other rows), its own cells
  in the rows of its participants are set, and new participants are appended;
- ``participants.json`` is merged key by key (the lab's column descriptions stay);
- ``dataset_description.json`` and ``README`` are written only where missing or
  vibrofocus's own;
- nothing is deleted: files of an earlier export that this one does not write stay;
- a symbolic link on the path of any file the export writes or merges (the file itself,
  a folder such as ``sub-01`` below the dataset, the manifest) is refused, even with
  ``force``: nothing is written or merged through a link, so a dataset someone else can
  write cannot make the export replace a file outside it. Every file is read and written
  without following links (``within=`` of :mod:`vibrofocus._atomic`); the participants
  files keep their line endings (``\r\n`` stays).

Each file is written atomically (:mod:`vibrofocus._atomic`); the manifest is updated
with what was written even when a later file fails.
"""

from __future__ import annotations

import contextlib
import errno as _errno
import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import OutputError

#: Columns of participants.tsv that BIDS defines and a lab describes in its own words: a
#: merge keeps the lab's description of these.
LAB_DESCRIBED = frozenset({"participant_id"})

__all__ = ["LAB_DESCRIBED", "MANIFEST_NAME", "merge_into_dataset", "merge_participants_tsv", "merge_participants_json",
           "read_manifest", "text_sha256", "write_manifest"]

#: The manifest of the files vibrofocus wrote into a dataset (relative path -> SHA-256).
MANIFEST_NAME = ".vibrofocus-bids.json"
_MANIFEST_FORMAT = "vibrofocus BIDS export manifest"
#: Shared files: written where missing or vibrofocus's own, never a conflict.
_SHARED = ("dataset_description.json", "README")
_NA = "n/a"


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def text_sha256(text: str) -> str:
    """SHA-256 of ``text`` as written (UTF-8), hex."""
    return _sha256(text.encode("utf-8"))


def read_manifest(root: str | os.PathLike) -> tuple[dict[str, str], dict[str, str]]:
    """The files vibrofocus wrote into the dataset ``root`` (empty if none).

    Returns
    -------
    (dict, dict)
        Relative path -> SHA-256, and relative path -> the source it was exported
        from (absent for the shared files). An unreadable or foreign manifest counts
        as none: every file is then treated as the lab's own.
    """
    data = _read_json(Path(root), MANIFEST_NAME)
    ok = isinstance(data, dict) and data.get("format") == _MANIFEST_FORMAT
    files, sources = (data.get("files"), data.get("sources")) if ok else (None, None)
    if not isinstance(files, dict):
        return {}, {}
    pick = lambda d: {k: v for k, v in d.items() if isinstance(k, str) and isinstance(v, str)}  # noqa: E731
    return pick(files), pick(sources) if isinstance(sources, dict) else {}


#: Largest manifest or participants file read, bytes (a lab's participants.tsv is far smaller).
_MAX_READ_BYTES = 64 * 2**20


def _read(root: Path, rel: str) -> bytes | None:
    """The bytes of ``root/rel`` read without following a link (None: missing, a link, not a regular file)."""
    from .._atomic import read_below

    try:
        return read_below(root, root / rel, limit=_MAX_READ_BYTES)
    except (OutputError, ValueError):
        return None


def _read_json(root: Path, rel: str) -> Any:
    data = _read(root, rel)
    try:
        return json.loads(data.decode("utf-8")) if data is not None else None
    except (ValueError, RecursionError):
        return None


def _file_sha256(root: Path, rel: str) -> str | None:
    data = _read(root, rel)
    return None if data is None else _sha256(data)


def _links_in_the_way(root: Path, names: Sequence[str]) -> list[str]:
    """The links (relative to ``root``) on the paths of ``names`` below ``root``, each once, sorted."""
    from .._atomic import link_below

    found = set()
    for rel in names:
        link = link_below(root, root / rel)
        if link is not None:
            found.add(link.relative_to(root).as_posix())
    return sorted(found)


def merge_participants_tsv(existing: str, columns: Sequence[str], rows: Sequence[Mapping[str, str]]) -> str | None:
    """``participants.tsv`` with ``rows`` merged into the text ``existing``.

    Parameters
    ----------
    existing : str
        The file's text (tab-separated, a header with ``participant_id``).
    columns : sequence of str
        vibrofocus's columns, ``participant_id`` first.
    rows : sequence of mapping
        vibrofocus's rows, each cell already formatted.

    Returns
    -------
    str or None
        The merged text: the lab's columns and rows kept cell for cell (a row none of
        whose cells change is kept byte for byte), vibrofocus's columns appended where
        missing, its cells set in its participants' rows, new participants appended.
        None when ``existing`` has no header with ``participant_id``.
    """
    newline = "\r\n" if "\r\n" in existing else "\n"
    lines = existing.split(newline)
    while lines and lines[-1] == "":
        lines.pop()
    if not lines:
        return None
    header = lines[0].split("\t")
    if "participant_id" not in header or len(set(header)) != len(header):
        return None
    key = header.index("participant_id")
    added = [c for c in columns if c not in header]
    full = header + added
    where = {c: full.index(c) for c in columns}
    ours = {r["participant_id"]: r for r in rows}
    out = [lines[0] + "".join(f"\t{c}" for c in added)]
    seen = set()
    for line in lines[1:]:
        cells = line.split("\t")
        pid = cells[key] if key < len(cells) else None
        if pid not in ours or pid in seen:
            out.append(line + f"\t{_NA}" * len(added) if added and line else line)
            continue
        seen.add(pid)
        cells += [_NA] * (len(full) - len(cells))
        for c in columns:
            cells[where[c]] = ours[pid][c]
        out.append("\t".join(cells))
    for row in rows:
        if row["participant_id"] not in seen:
            cells = [_NA] * len(full)
            for c in columns:
                cells[where[c]] = row[c]
            out.append("\t".join(cells))
    return newline.join(out) + newline


def merge_participants_json(existing: str, columns: Mapping[str, Any]) -> str | None:
    """``participants.json`` with vibrofocus's column descriptions merged into ``existing``.

    Returns
    -------
    str or None
        The lab's keys kept (in their order), vibrofocus's set, except those of
        :data:`LAB_DESCRIBED` that the lab describes (its words stay); None when
        ``existing`` is not a JSON object.
    """
    try:
        data = json.loads(existing)
    except (ValueError, RecursionError):
        return None
    if not isinstance(data, dict):
        return None
    # participant_id is BIDS's column, which the lab describes its own way; vibrofocus's
    # own columns (source_id, simulated) get vibrofocus's current description.
    data.update({k: v for k, v in columns.items() if k not in LAB_DESCRIBED or k not in data})
    text = json.dumps(data, indent=2) + "\n"
    return text.replace("\n", "\r\n") if "\r\n" in existing else text  # the file's line endings stay


def _conflict_message(root: Path, conflicts: list[str]) -> str:
    shown = ", ".join(conflicts[:3]) + (f" and {len(conflicts) - 3} more" if len(conflicts) > 3 else "")
    return (f"the BIDS dataset {root} already holds {len(conflicts)} file(s) where the export would write, which "
            f"vibrofocus did not write there (or which were edited since, or were exported from another source): {shown}; nothing was changed. Pass --force "
            f"(force=True) to replace them, or export into another folder")


def merge_into_dataset(
    root: Path,
    *,
    files: Mapping[str, str],
    shared: Mapping[str, str],
    participant_columns: Mapping[str, Mapping[str, Any]],
    participant_rows: Sequence[Mapping[str, str]],
    participants_tsv: str,
    participants_json: str,
    source: str | None = None,
    force: bool = False,
) -> list[str]:
    """Write vibrofocus's files into the existing dataset folder ``root`` (see the module's rules).

    Parameters
    ----------
    root : Path
        An existing folder (a symbolic link already resolved).
    files : mapping
        Relative path -> text of each file vibrofocus owns (events files and sidecars).
    shared : mapping
        ``dataset_description.json`` and ``README`` -> text: written where missing or
        vibrofocus's own, else left as they are.
    participant_columns, participant_rows
        vibrofocus's columns (descriptions) and rows (formatted cells) of the participants files.
    participants_tsv, participants_json : str
        The files' text where the dataset has none.
    source : str, optional
        Where the data comes from (the source file's resolved path): a file of
        ``files`` is replaced only if an export of the same source wrote it.
    force : bool
        Replace files in the way (not vibrofocus's, or edited since it wrote them).

    Returns
    -------
    list of str
        The shared files kept as the lab's own (``dataset_description.json``, ``README``).

    Raises
    ------
    OutputError
        A symbolic link on the path of a file it would write or merge, even with
        ``force``, or a file in the way (nothing is changed); or a write failed (the
        files written before stay, and are in the manifest).
    """
    from .._atomic import atomic_write, output_target

    names = [*files, *shared, "participants.tsv", "participants.json", MANIFEST_NAME]
    links = _links_in_the_way(root, names)
    if links:
        shown = "; ".join(f"{link} is a link: refused" for link in links[:3])
        more = f" (and {len(links) - 3} more)" if len(links) > 3 else ""
        raise OutputError(f"the BIDS dataset {root} holds links where the export would write: {shown}{more}; "
                          "nothing was changed. An export never writes through a link, even with --force: put the "
                          "folder or file itself there, or export into another folder", errno=_errno.ELOOP,
                          path=str(root))
    manifest, sources = read_manifest(root)

    def ours(rel: str, *, same_source: bool = True) -> bool:
        if same_source and sources.get(rel) != source:
            return False
        return rel in manifest and _file_sha256(root, rel) == manifest[rel]

    plan: dict[str, str] = {}
    conflicts: list[str] = []
    kept: list[str] = []
    for rel, text in files.items():
        path = root / rel
        output_target(path, "BIDS file")  # a folder, device or link to nothing in the way is refused here
        if (path.exists() or path.is_symlink()) and not ours(rel):
            conflicts.append(rel)
        plan[rel] = text
    for name, text in shared.items():
        path = root / name
        if not (path.exists() or path.is_symlink()) or ours(name, same_source=False):
            plan[name] = text
        else:
            kept.append(name)
    for name, fresh, merge in (("participants.tsv", participants_tsv,
                                lambda old: merge_participants_tsv(old, list(participant_columns), participant_rows)),
                               ("participants.json", participants_json,
                                lambda old: merge_participants_json(old, participant_columns))):
        path = root / name
        output_target(path, name)
        if not (path.exists() or path.is_symlink()):
            plan[name] = fresh
            continue
        data = _read(root, name)
        try:
            # Bytes decoded as they are: universal newlines would turn the file's \r\n into \n.
            merged = merge(data.decode("utf-8")) if data is not None else None
        except UnicodeDecodeError:
            merged = None
        if merged is None:
            conflicts.append(f"{name} (cannot be merged: not UTF-8 with a participant_id column / a JSON object)")
            plan[name] = fresh
        else:
            plan[name] = merged
    if conflicts and not force:
        raise OutputError(_conflict_message(root, conflicts), path=str(root))
    written: dict[str, str] = {}

    def new_sources(done: Mapping[str, str]) -> dict[str, str]:
        return {rel: source for rel in done if rel in files and source is not None}

    try:
        for rel, text in plan.items():
            # Below root only, no link followed: folders made with mkdirat, the file renamed in its folder.
            with atomic_write(root / rel, "w", newline="", what="BIDS file", within=root, parents=True) as fh:
                fh.write(text)
            written[rel] = _sha256(text.encode("utf-8"))
    except BaseException:
        # What was written is vibrofocus's: listed, so a second try replaces it.
        if written:
            with contextlib.suppress(OutputError):
                write_manifest(root, {**manifest, **written}, {**sources, **new_sources(written)})
        raise
    write_manifest(root, {**manifest, **written}, {**sources, **new_sources(written)})
    return kept


def write_manifest(root: Path, files: Mapping[str, str], sources: Mapping[str, str] | None = None) -> None:
    """Write the manifest of ``root``: the files vibrofocus wrote (relative path -> SHA-256, and -> source).

    The participants files are left out: they are merged, never owned.
    """
    from .._atomic import write_text

    files = {k: v for k, v in files.items() if k not in ("participants.tsv", "participants.json")}
    text = json.dumps({"format": _MANIFEST_FORMAT, "version": 1,
                       "note": "Files vibrofocus wrote into this BIDS dataset and their SHA-256; vibrofocus "
                               "replaces only these, unedited. Keep this file.",
                       "files": dict(sorted(files.items())),
                       "sources": dict(sorted((k, v) for k, v in (sources or {}).items() if k in files))},
                      indent=2) + "\n"
    write_text(root / MANIFEST_NAME, text, what="BIDS export manifest", within=root)
