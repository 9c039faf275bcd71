"""info and recover: small commands over a bag."""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from pathlib import Path

from recorder.bag import BagError, bag_info, recover


def info_main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='info', description='Duration, topics, types, '
                                     'message counts, start and end of a bag.')
    parser.add_argument('bag', type=Path)
    options = parser.parse_args(argv)
    try:
        info = bag_info(options.bag)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    print(format_info(info))
    return 0


def _when(ns: int) -> str:
    # Simulated time starts at 0; wall-clock recordings carry the epoch.
    if ns < 10 ** 17:
        return f'{ns / 1e9:.3f} s'
    return datetime.fromtimestamp(ns / 1e9, tz=timezone.utc).isoformat()


def format_info(info) -> str:
    lines = [f'file:      {info.path}',
             f'duration:  {info.duration_s:.3f} s',
             f'start:     {_when(info.start_ns)}',
             f'end:       {_when(info.end_ns)}',
             f'messages:  {info.message_count}',
             'topics:']
    width = max((len(t) for t in info.topics), default=0)
    for name, topic in sorted(info.topics.items()):
        lines.append(f'  {name:{width}s}  {topic.message_count:8d}  {topic.type}')
    return '\n'.join(lines)


def recover_main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog='recover', description='Make a valid bag of what a killed recording holds; the '
        'damaged file is kept as <file>.damaged. An intact bag is left as it is.')
    parser.add_argument('bag', type=Path, help='bag folder or .mcap file')
    options = parser.parse_args(argv)
    try:
        result = recover(options.bag)
    except BagError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    info = result.info
    if result.intact:
        print(f'{info.path} is intact ({info.message_count} messages, {info.duration_s:.3f} s, '
              'closed properly): nothing to recover, left as it is')
        return 0
    print(f'recovered {info.message_count} messages ({info.duration_s:.3f} s) into {info.path}; '
          f'{result.lost_bytes} bytes at the end could not be read')
    return 0
