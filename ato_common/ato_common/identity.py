"""The identity of what a plant simulates: the scenario's name and a hash of the scenario as
resolved (every field after loading, presets and TTOBench files read, defaults filled in).

The plant publishes it latched (``TOPICS['identity']``); the controller and the profile compare
it with the scenario they loaded and refuse to run on another one. ``origin`` (where the file
was read from) is left out: the same scenario read from another path is the same scenario.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math

import numpy as np

IDENTITY_FIELDS = ('scenario', 'sha256')


def _canonical(value):
    """A JSON-able form of a resolved scenario, the same for equal scenarios on any machine."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _canonical(getattr(value, f.name))
                for f in dataclasses.fields(value) if f.name != 'origin'}
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_canonical(v) for v in value.tolist()]
    if isinstance(value, (bool, str, int)) or value is None:
        return value
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else repr(value)  # JSON has no inf, nan
    if isinstance(value, np.integer):
        return int(value)
    if hasattr(value, '__dict__'):
        return {'__class__': type(value).__name__, **_canonical(vars(value))}
    raise TypeError(f'cannot take the identity of a {type(value).__name__} in a scenario')


def scenario_hash(scenario) -> str:
    text = json.dumps(_canonical(scenario), sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(text.encode()).hexdigest()


def scenario_identity(scenario) -> str:
    """The identity text: JSON ``{"scenario": name, "sha256": hash}``."""
    return json.dumps({'scenario': scenario.name, 'sha256': scenario_hash(scenario)},
                      sort_keys=True)


def parse_identity(text: str) -> dict[str, str]:
    """The fields of an identity text; ValueError naming what is wrong."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f'plant identity is not JSON: {error}') from None
    if not isinstance(data, dict) or any(not isinstance(data.get(k), str)
                                         for k in IDENTITY_FIELDS):
        raise ValueError(f'plant identity needs the strings {", ".join(IDENTITY_FIELDS)}, '
                         f'got {text!r}')
    return {k: data[k] for k in IDENTITY_FIELDS}


def identity_mismatch(own: str, plant: str) -> str:
    """'' if the plant simulates the scenario of ``own`` (both identity texts), else why not,
    naming both."""
    mine, theirs = parse_identity(own), parse_identity(plant)
    if mine == theirs:
        return ''
    same_name = mine['scenario'] == theirs['scenario']
    return (f"the plant simulates scenario {theirs['scenario']} (sha256 "
            f"{theirs['sha256'][:12]}), this node was given {mine['scenario']} (sha256 "
            f"{mine['sha256'][:12]})" + (': same name, different content' if same_name else '')
            + '; start both with the same scenario parameter')
