"""A campaign's rows on disk: the Parquet dataset ``<out>/<name>/rows/``, one file per finished
row, written atomically, merged into one file when the campaign is complete.

Every file carries in its schema metadata (under DATA_KEY, JSON) what its rows stand on: the
campaign's identity and fingerprint (seed, draws, scenarios, laws, uncertainty, window), the
uncertainty in words, the run's end rule, the tuning artefact the laws' gains came from and the
commit of the code that ran them (ato_campaigns.engine.data_description); a file read alone
says where it comes from (``file_description``). A folder holds the rows of one fingerprint:
running another version of a campaign into the folder of an earlier one is refused with what
differs (FolderConflict), never mixed.
"""

from __future__ import annotations

import json
import os
import uuid
from pathlib import Path
from typing import Any, Mapping

from ato_common.validation import ConfigError

#: the key of a row: which run it is
KEY = ('scenario', 'law', 'draw')
#: the schema metadata key of a file's description
DATA_KEY = b'ato_campaign'


class FolderConflict(ConfigError):
    """The folder holds rows of another version of the campaign (another fingerprint)."""


def rows_folder(out: Path, name: str) -> Path:
    return out / name / 'rows'


def _write(frame, path: Path, description: Mapping[str, Any] | None) -> Path:
    """``frame`` as the Parquet file ``path``, written under a temporary name, then renamed,
    with ``description`` in its schema metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    table = pa.Table.from_pandas(frame, preserve_index=False)
    if description is not None:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), DATA_KEY:
                                               json.dumps(description, sort_keys=True).encode()})
    tmp = path.with_suffix('.tmp')
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def write_row(folder: Path, row: dict, description: Mapping[str, Any] | None = None) -> Path:
    """One finished row as a Parquet file of the dataset, written atomically (a temporary name,
    then a rename): an interrupted campaign leaves whole rows only."""
    import pandas as pd
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f'part-{row["draw"]:06d}-{uuid.uuid4().hex}.parquet'
    return _write(pd.DataFrame([row]), path, description)


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob('*.parquet'), key=lambda p: (p.stat().st_mtime_ns, p.name)) \
        if folder.is_dir() else []


def read_rows(folder: Path, fingerprint: str | None = None):
    """The dataset as a DataFrame (empty if none); only the rows of ``fingerprint`` if given,
    one per key and fingerprint (the latest written if a row was written twice)."""
    import pandas as pd
    files = _files(folder)
    if not files:
        return pd.DataFrame()
    table = pd.concat([pd.read_parquet(p) for p in files], ignore_index=True)
    if fingerprint is not None:
        table = table[table['fingerprint'] == fingerprint]
    return table.drop_duplicates([*KEY, 'fingerprint'], keep='last').sort_values(
        ['scenario', 'law', 'draw']).reset_index(drop=True)


def compact(folder: Path, description: Mapping[str, Any] | None = None) -> None:
    """Merge the files of the dataset into one, with ``description`` (after a complete
    campaign)."""
    if len(list(folder.glob('part-*.parquet'))) < 2:
        return
    merged = _write(read_rows(folder), folder / f'rows-{uuid.uuid4().hex}.parquet',
                    description)
    for p in folder.glob('*.parquet'):
        if p != merged:
            p.unlink()


def file_description(path: Path) -> dict | None:
    """What a file's rows stand on (its DATA_KEY metadata), None if it has none."""
    import pyarrow.parquet as pq
    metadata = pq.read_schema(path).metadata or {}
    return json.loads(metadata[DATA_KEY]) if DATA_KEY in metadata else None


def stored_versions(folder: Path) -> dict[str, dict | None]:
    """Each fingerprint whose rows the folder holds, with the description of one of its files
    (None for files written without one)."""
    import pyarrow.parquet as pq
    versions: dict[str, dict | None] = {}
    for path in _files(folder):
        description = file_description(path)
        if description is not None and 'fingerprint' in description:
            versions.setdefault(description['fingerprint'], description)
            continue
        fingerprints = pq.read_table(path, columns=['fingerprint']).column(0).to_pylist()
        for fingerprint in set(fingerprints):
            versions.setdefault(fingerprint, None)
    return versions


def check_folder(folder: Path, fingerprint: str, identity: Mapping[str, Any]) -> None:
    """Refuse (FolderConflict) a folder that holds rows of another fingerprint, saying what
    differs from ``identity`` (the campaign's, whose hash is ``fingerprint``)."""
    others = {k: v for k, v in stored_versions(folder).items() if k != fingerprint}
    if not others:
        return
    other, description = next(iter(others.items()))
    theirs = (description or {}).get('identity')
    if theirs is None:
        differs = 'written before the rows described their campaign'
    else:
        changed = [key for key in sorted(set(theirs) | set(identity))
                   if theirs.get(key) != identity.get(key)]
        differs = 'it differs in ' + ', '.join(
            f'{key} ({theirs.get(key)} there, {identity.get(key)} here)'
            if key in ('seed', 'draws', 'end_time_s') else key for key in changed)
    raise FolderConflict(
        f'{folder} holds the rows of another version of this campaign (fingerprint {other}; '
        f'this one is {fingerprint}: {differs}). A folder never mixes two versions: give this '
        'campaign another name (its rows go to a folder of their own), or move that folder '
        'away.')
