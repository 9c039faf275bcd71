import math

import pytest

from ato_common import units
from ato_common.trains import DavisResistance, TRAIN_PRESETS, steady_speed, train_preset


def test_speed_and_mass_conversions():
    assert units.kmh_to_mps(360.0) == pytest.approx(100.0)
    assert units.mps_to_kmh(100.0) == pytest.approx(360.0)
    assert units.tonnes_to_kg(510.0) == 510000.0
    assert units.kn_to_n(300.0) == 300000.0
    assert units.joules_to_kwh(3.6e6) == 1.0


def test_per_mille_grade_is_the_sine_of_the_track_angle():
    assert units.per_mille_to_sine(0.0) == 0.0
    assert units.per_mille_to_sine(12.0) == pytest.approx(0.012, rel=1e-4)
    assert units.per_mille_to_sine(-12.0) == -units.per_mille_to_sine(12.0)


def test_davis_per_tonne_to_si_matches_the_papers_notes():
    # Tan et al. CRH380A: 5.6 + 0.036 V + 0.00121 V^2 N/t -> a = 5.6e-3, b = 1.296e-4, c = 1.568e-5
    a, b, c = units.davis_per_tonne_to_per_kg(5.6, 0.036, 0.00121)
    assert a == pytest.approx(5.6e-3)
    assert b == pytest.approx(1.296e-4)
    assert c == pytest.approx(1.568e-5, rel=1e-3)


def test_davis_per_kn_uses_the_weight_of_a_tonne():
    # CRH2: 0.88 + 0.00744 V + 0.000114 V^2 N/kN times g gives 8.63 / 0.0730 / 0.00112 N/t
    a, b, c = units.davis_per_kn_to_per_kg(0.88, 0.00744, 0.000114, gravity=9.81)
    assert a * 1000 == pytest.approx(8.63, rel=2e-3)
    assert b * 1000 / 3.6 == pytest.approx(0.0730, rel=2e-3)
    assert c * 1000 / 12.96 == pytest.approx(0.00112, rel=2e-3)


def test_crh3_preset_carries_luo_xu_tables_in_si():
    train = train_preset('crh3_luo_xu')
    assert train.mass_kg == 510000.0
    assert train.davis.per_kg(train.mass_kg)[0] == pytest.approx(7.75e-3)
    assert train.davis.per_kg(train.mass_kg)[1] == pytest.approx(2.2777e-4, rel=1e-4)
    assert train.davis.per_kg(train.mass_kg)[2] == pytest.approx(1.6589e-5, rel=1e-4)
    # the corrected nominal cv of Table 2 (0.06318, printed 0.6318)
    assert train.davis_nominal.per_kg(train.mass_kg)[1] == pytest.approx(2.2745e-4, rel=1e-4)
    # resistance at 300 km/h is about 72 kN (shared/papers/README.md)
    assert train.davis.force(units.kmh_to_mps(300)) == pytest.approx(72.5e3, rel=0.02)
    assert train.sources


def test_traction_characteristic_is_force_then_power_limited():
    traction = train_preset('crh3_luo_xu').traction
    assert traction.max_traction_at(0.0) == 300e3
    assert traction.max_traction_at(80.0) == pytest.approx(8.8e6 / 80.0)
    low, high = traction.limits_at(50.0)
    assert low < 0.0 < high


def test_every_preset_builds_and_unknown_is_rejected_with_the_list():
    for name in TRAIN_PRESETS:
        assert train_preset(name).name == name
    with pytest.raises(KeyError, match='valid: crh'):
        train_preset('tgv')


def test_steady_speed_balances_force_and_resistance():
    train = train_preset('crh3_luo_xu')
    v = steady_speed(train, 100e3)
    assert train.davis.force(v) == pytest.approx(100e3)
    assert math.isnan(steady_speed(train, 0.0, grade_sine=-0.5)) or steady_speed(train, 0.0) != v


def test_resistance_opposes_motion_with_the_sign_of_speed():
    davis = DavisResistance(1000.0, 10.0, 1.0)
    assert davis.force(10.0) == davis.force(-10.0) == 1000.0 + 100.0 + 100.0
