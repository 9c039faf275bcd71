"""The two configurations of every law's settings: ``published`` and ``tuned``.

- ``published``: the law's own defaults: the paper's law and gains as printed where the paper
  is self-consistent, converted to SI once (``ato_common.units``); every deviation is a named
  setting, documented with the law, and off unless the paper leaves no choice.
- ``tuned``: the settings found by the suite's one tuning procedure (``ato_campaigns.tuning``,
  ``make tune``), the same for every law including the PID: a search over the law's admissible
  settings (``setting(..., admissible=...)``) on training draws of the campaign's uncertainty.
  Each result is a versioned artefact in this package, ``tuned/<train>/<law>.json``, holding
  the settings and the procedure, budget, seeds, scenario, commit and date that produced it.

:func:`settings_for` gives a law's settings (the values that differ from its defaults) for a
configuration and a train (its preset name, ``scenario.train.name``); a law or train without a
tuned artefact raises :class:`GainsUnavailable`, naming the ones there are. The controller node
takes the configuration as its parameter ``gains``, ``run_offline`` as its argument ``gains``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

from ato_controller_node import laws as registry
from ato_controller_node.laws.base import setting_fields, validated_settings

#: the configurations, the default first
GAINS = ('published', 'tuned')
#: where the tuned artefacts live: one file per train and law
TUNED_DIR = Path(__file__).resolve().parent / 'tuned'
#: the version of the artefact format
FORMAT = 1


class GainsUnavailable(LookupError):
    """No settings of that configuration for that law and train; the message says why."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0])


@dataclass(frozen=True)
class TunedArtefact:
    """One tuned artefact: the law's settings and how they were produced (the JSON as read)."""

    law: str
    train: str
    settings: Mapping[str, Any]
    record: Mapping[str, Any]     # the whole file: procedure, budget, seeds, commit, result
    path: Path


def artefact_path(law: str, train: str, folder: Path | None = None) -> Path:
    return (folder or TUNED_DIR) / train / f'{law}.json'


def check_gains(value: Any) -> str | None:
    """None if ``value`` names a configuration, else why not."""
    if value not in GAINS:
        return f"gains '{value}' is not valid; valid: {', '.join(GAINS)}"
    return None


def available(folder: Path | None = None) -> list[tuple[str, str]]:
    """(train, law) of every tuned artefact there is, sorted."""
    root = folder or TUNED_DIR
    return sorted((path.parent.name, path.stem) for path in root.glob('*/*.json'))


def read_artefact(path: Path) -> TunedArtefact:
    """A tuned artefact, checked: ValueError naming the file and what is wrong."""
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f'{path}: not a readable tuned-gains file: {error}') from None
    if not isinstance(record, dict) or record.get('format') != FORMAT:
        raise ValueError(f'{path}: not a tuned-gains file of format {FORMAT}')
    law, train, settings = record.get('law'), record.get('train'), record.get('settings')
    if law not in registry.LAWS:
        raise ValueError(f'{path}: unknown law {law!r}; valid: '
                         f"{', '.join(sorted(registry.LAWS))}")
    if (law, train) != (path.stem, path.parent.name):
        raise ValueError(f'{path}: holds {law} on {train}, not what its name says')
    if not isinstance(settings, dict):
        raise ValueError(f'{path}: settings must be a mapping')
    try:
        validated_settings(registry.LAWS[law].Settings, settings)
    except ValueError as error:
        raise ValueError(f'{path}: {error}') from None
    return TunedArtefact(str(law), str(train), settings, record, path)


def tuned_artefact(law: str, train: str, folder: Path | None = None) -> TunedArtefact:
    path = artefact_path(law, train, folder)
    if not path.is_file():
        there = ', '.join(f'{t_law} on {t_train}' for t_train, t_law in available(folder))
        raise GainsUnavailable(f'no tuned gains of {law} for the train {train} '
                               f'(tuned: {there or "none"}); run make tune or use '
                               'gains: published')
    return read_artefact(path)


def settings_for(law: str, gains: str, train: str, folder: Path | None = None
                 ) -> dict[str, Any]:
    """The settings of ``law`` in configuration ``gains`` for the train preset ``train``: {}
    for ``published`` (the law's defaults), the artefact's for ``tuned``."""
    reason = check_gains(gains)
    if reason:
        raise ValueError(reason)
    if law not in registry.LAWS:
        raise KeyError(f"unknown law '{law}'; valid: {', '.join(sorted(registry.LAWS))}")
    if gains == 'published':
        return {}
    return dict(tuned_artefact(law, train, folder).settings)


def configured(gains: str, train: str, laws: Iterable[str],
               overrides: Mapping[str, Mapping[str, Any]] | None = None,
               folder: Path | None = None) -> dict[str, dict[str, Any]]:
    """The settings of every law of ``laws`` in configuration ``gains`` with ``overrides`` (a
    law's explicit settings) on top: what ``ControllerHost`` takes as ``settings``."""
    result: dict[str, dict[str, Any]] = {}
    for law in laws:
        result[law] = {**settings_for(law, gains, train, folder),
                       **dict((overrides or {}).get(law, {}))}
    for law, values in (overrides or {}).items():
        result.setdefault(law, dict(values))
    return result


def published_settings(law: str) -> dict[str, Any]:
    """Every setting of ``law`` at its published value (its defaults), by name."""
    settings_type = registry.LAWS[law].Settings
    defaults = settings_type()
    return {f.name: getattr(defaults, f.name) for f in setting_fields(settings_type)}
