"""Evidence for a paper's claim, as a reproduction test measured it.

A reproduction test calls :func:`record` with the paper's figure and the suite's, once its
assertions have passed; ``make reproduce`` (``ato_tools.reproduction``) runs those tests with
:data:`LOG_VARIABLE` naming a file and writes the "paper versus suite" page of the docs
(``docs/results/reproduction.md``) from what they recorded. So every figure on that page is one
a test measured in that run, never a typed one. Without the variable, :func:`record` writes
nothing and the tests run as usual.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping

#: the environment variable that names the file the claims are appended to (JSON lines)
LOG_VARIABLE = 'ATO_REPRODUCTION_LOG'
#: a row that tests what the suite adds to a paper (an option of its own, actuator limits the
#: paper does not have, a sampled law the paper runs in continuous time): it says nothing about
#: the paper's claims either way
SUITE_EXTENSION = "suite extension, outside the paper's claims"
#: a row whose figures differ from the paper's by more than COMPARABLE_FACTOR either way: the
#: set-ups differ too much (a reconstructed law, another trajectory) for a verdict
NOT_COMPARABLE = 'not comparable'
COMPARABLE_FACTOR = 10.0
VERDICTS = ('reproduced', 'partly reproduced', 'not reproduced', SUITE_EXTENSION,
            NOT_COMPARABLE)


@dataclass(frozen=True)
class Claim:
    """One claim of a paper and what the suite measured for it.

    ``paper`` is the stem of the paper's note in ``docs/papers``; ``setup`` says how the suite
    tried it (scenario, plant, rate, what differs from the paper); ``reason`` says why a claim
    is not (or only partly) reproduced."""

    paper: str
    claim: str
    paper_figure: str
    suite_figure: str
    setup: str
    verdict: str
    reason: str = ''

    def __post_init__(self):
        if self.verdict not in VERDICTS:
            raise ValueError(f'verdict {self.verdict!r} is not one of {", ".join(VERDICTS)}')
        for name in ('paper', 'claim', 'paper_figure', 'suite_figure', 'setup'):
            if not getattr(self, name).strip():
                raise ValueError(f'a claim needs a {name}')
        if self.verdict != 'reproduced' and not self.reason.strip():
            raise ValueError(f'a claim {self.verdict} needs its reason')


def incomparable(paper: Mapping[str, float], suite: Mapping[str, float],
                 factor: float = COMPARABLE_FACTOR) -> dict[str, float]:
    """The figures of ``suite`` that differ from ``paper``'s of the same name by more than
    ``factor`` either way, with the ratio suite / paper (a sign change or a zero: inf)."""
    far = {}
    for name, value in suite.items():
        if name not in paper:
            continue
        reference = paper[name]
        ratio = value / reference if reference != 0.0 and value / reference > 0.0 else math.inf
        if not 1.0 / factor <= ratio <= factor:
            far[name] = ratio
    return far


def record(claim: Claim) -> Claim:
    """Append the claim, with the test that measured it, to the log named by LOG_VARIABLE."""
    path = os.environ.get(LOG_VARIABLE)
    if path:
        entry = asdict(claim)
        entry['test'] = os.environ.get('PYTEST_CURRENT_TEST', '').split(' ')[0]
        with open(path, 'a', encoding='utf-8') as handle:
            handle.write(json.dumps(entry) + '\n')
    return claim


def read_claims(path: Path) -> list[dict]:
    """The claims a run recorded, in order (an absent file: none)."""
    path = Path(path)
    if not path.exists():
        return []
    claims = []
    for number, line in enumerate(path.read_text(encoding='utf-8').splitlines(), 1):
        try:
            entry = json.loads(line)
            Claim(**{k: v for k, v in entry.items() if k != 'test'})
        except (ValueError, TypeError) as error:
            raise ValueError(f'{path}:{number}: not a recorded claim: {error}') from None
        claims.append(entry)
    return claims
