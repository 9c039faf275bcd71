"""Print the README's topic and parameter tables from the code (tests/test_readme.py checks that
the README lists them): run with `. scripts/env.sh; python scripts/readme_tables.py`."""

from ato_common.conventions import TOPICS
from ato_controller_node.node import NODE_PARAMS, gain_params
from profile_node.node import PARAMS as PROFILE_PARAMS
from train_plant_node.node import PARAMS as PLANT_PARAMS


def main() -> None:
    print('| topic | type | QoS | units | publisher | subscribers | content |')
    print('|---|---|---|---|---|---|---|')
    for t in TOPICS.values():
        print(f'| `{t.name}` | `{t.type_name}` | {t.qos.describe()} | {t.units} | '
              f'{t.publisher} | {t.subscribers} | {t.description} |')
    for title, params in (('train_plant_node', PLANT_PARAMS), ('profile_node', PROFILE_PARAMS),
                          ('ato_controller_node', NODE_PARAMS + tuple(gain_params()))):
        print(f'\n#### {title}\n\n| parameter | default | range | set at run time | description |')
        print('|---|---|---|---|---|')
        for p in params:
            if p.minimum is not None:
                valid = f'{p.minimum:g} .. {p.maximum:g}'
            else:
                valid = ', '.join(p.choices) if p.choices else ''
            default = str(p.default).lower() if isinstance(p.default, bool) else p.default
            print(f'| `{p.name}` | `{default}` | {valid} | {"no" if p.read_only else "yes"} | '
                  f'{p.description} |')


if __name__ == '__main__':
    main()
