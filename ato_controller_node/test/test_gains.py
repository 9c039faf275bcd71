"""The two configurations of the laws' settings (ato_controller_node.gains): published (the
laws' defaults) and tuned (versioned artefacts per law and train), and the node's parameters
built from them."""

import json

import pytest

from ato_controller_node import gains
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import admissible_fields, setting_fields


def write(folder, law='pid', train='crh3_luo_xu', **changes):
    record = {'format': gains.FORMAT, 'law': law, 'train': train,
              'settings': {'kp_position': 0.3, 'kd_speed': 1.5, 'ki_position': 0.02}}
    record.update(changes)
    path = gains.artefact_path(law, train, folder)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record))
    return path


def test_published_is_the_laws_defaults_and_tuned_is_the_artefact(tmp_path):
    assert gains.GAINS == ('published', 'tuned')
    assert gains.settings_for('pid', 'published', 'crh3_luo_xu', tmp_path) == {}
    write(tmp_path)
    tuned = gains.settings_for('pid', 'tuned', 'crh3_luo_xu', tmp_path)
    assert tuned == {'kp_position': 0.3, 'kd_speed': 1.5, 'ki_position': 0.02}
    assert gains.available(tmp_path) == [('crh3_luo_xu', 'pid')]
    settings = gains.configured('tuned', 'crh3_luo_xu', ['pid'], {'pid': {'kd_speed': 2.0}},
                                tmp_path)
    assert settings == {'pid': {'kp_position': 0.3, 'kd_speed': 2.0, 'ki_position': 0.02}}


def test_a_missing_or_bad_artefact_says_what_is_wrong(tmp_path):
    write(tmp_path)
    with pytest.raises(gains.GainsUnavailable, match='no tuned gains of luo_xu for the train '
                       r'crh3_luo_xu \(tuned: pid on crh3_luo_xu\); run make tune'):
        gains.settings_for('luo_xu', 'tuned', 'crh3_luo_xu', tmp_path)
    with pytest.raises(ValueError, match="gains 'best' is not valid; valid: published, tuned"):
        gains.settings_for('pid', 'best', 'crh3_luo_xu', tmp_path)
    write(tmp_path, settings={'kd_speed': -1.0})
    with pytest.raises(ValueError, match=r'pid.json: kd_speed must be within'):
        gains.settings_for('pid', 'tuned', 'crh3_luo_xu', tmp_path)
    moved = write(tmp_path, law='luo_xu', settings={}).rename(
        gains.artefact_path('pid', 'crh3_luo_xu', tmp_path))
    with pytest.raises(ValueError, match='holds luo_xu on crh3_luo_xu, not what its name says'):
        gains.read_artefact(moved)
    gains.artefact_path('pid', 'crh3_luo_xu', tmp_path).write_text('{not json')
    with pytest.raises(ValueError, match='not a readable tuned-gains file'):
        gains.settings_for('pid', 'tuned', 'crh3_luo_xu', tmp_path)


def test_the_committed_artefacts_are_valid_and_record_how_they_were_made():
    for train, law in gains.available():
        artefact = gains.tuned_artefact(law, train)
        record = artefact.record
        assert set(artefact.settings) <= {f.name for f in admissible_fields(LAWS[law].Settings)}
        for key in ('procedure', 'budget', 'training', 'result', 'produced'):
            assert key in record, (law, train, key)
        assert record['training']['seed'] != 2026   # not the campaign's evaluation seed
        assert record['produced']['commit']


def test_the_node_declares_every_setting_with_the_configurations_defaults():
    from ato_controller_node.node import NODE_PARAMS, gain_params
    names = {p.name for p in NODE_PARAMS}
    assert {'gains', 'envelope'} <= names
    gains_param = next(p for p in NODE_PARAMS if p.name == 'gains')
    assert gains_param.check('tuned') is None and gains_param.read_only
    assert gains_param.check('best') == "gains 'best' is not valid; valid: published, tuned"
    params = {p.name: p for p in gain_params({'pid': {'kd_speed': 2.5}})}
    assert params['pid.kd_speed'].default == 2.5
    assert params['pid.kp_position'].default == 0.48
    assert {'envelope.tracking_time_s', 'envelope.catch_up_speed_mps'} <= set(params)
    for law, cls in LAWS.items():
        assert {f'{law}.{f.name}' for f in setting_fields(cls.Settings)} <= set(params)
