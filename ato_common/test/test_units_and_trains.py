import math

import pytest

from ato_common import units
from ato_common.trains import TRAIN_PRESETS, DavisResistance, steady_speed, train_preset


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
    # resistance at 300 km/h is about 72 kN (docs/papers/luo_xu.md)
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


def test_whole_train_davis_in_kn_and_kmh_converts_to_newtons():
    # Mao et al. 2017 mode (i), reading (A): 2.25 kN, -1.9e-3 kN/(km/h), 3.2e-4 kN/(km/h)^2
    a, b, c = units.davis_kn_kmh_to_n(2.25, -1.9e-3, 3.2e-4)
    assert a == pytest.approx(2250.0)
    assert b == pytest.approx(-6.84)
    assert c == pytest.approx(4.1472)
    # the tunnel mode's c = 9.2e-4 -> 11.92 N s^2/m^2
    assert units.davis_kn_kmh_to_n(0.0, 0.0, 9.2e-4)[2] == pytest.approx(11.9232)


def test_crh5_preset_carries_mao_table_1():
    train = train_preset('crh5_4car_mao')
    assert [c.mass_kg for c in train.cars] == [50e3, 48e3, 51e3, 53e3]
    assert train.mass_kg == 202e3
    assert [c.a_mps2 for c in train.cars] == pytest.approx([6.63e-3, 5.43e-3, 5.43e-3, 6.63e-3])
    assert [c.b_per_s for c in train.cars] == pytest.approx(
        [0.06382 * 3.6e-3, 0.07041 * 3.6e-3, 0.07041 * 3.6e-3, 0.06382 * 3.6e-3])
    assert train.cars[0].c_per_m == pytest.approx(0.00107 * 12.96e-3)
    assert all(c.c_per_m == 0.0 for c in train.cars[1:])
    assert [c.powered for c in train.cars] == [False, True, True, False]
    assert [(k.stiffness_n_per_m, k.damping_n_s_per_m) for k in train.couplers] == [
        (500e6, 2e4), (650e6, 2.2e4), (500e6, 2e4)]
    assert train.actuator_names == ('car_2', 'car_3')
    # whole-train Davis is the sum of the cars' resistances
    v = 50.0
    per_car = sum(c.mass_kg * (c.a_mps2 + c.b_per_s * v + c.c_per_m * v * v) for c in train.cars)
    assert train.davis.force(v) == pytest.approx(per_car)


def test_crh2_preset_carries_mao_table_2():
    train = train_preset('crh2_4car_mao')
    assert [c.mass_kg for c in train.cars] == [42.8e3, 48e3, 46.5e3, 42e3]
    assert train.cars[1].a_mps2 == pytest.approx(9.03e-3)
    assert [k.stiffness_n_per_m for k in train.couplers] == [800e6, 600e6, 800e6]


def test_crh380al_preset_is_liu_li_890_t_with_the_recommended_resistance():
    train = train_preset('crh380al_liu_li')
    assert train.mass_kg == 890e3
    # docs/papers/liu_li.md: a0 = 4984 N, a1 = 115.34 N s/m, a2 = 13.957 N s^2/m^2
    assert train.davis.a_n == pytest.approx(4984.0)
    assert train.davis.b_n_s_per_m == pytest.approx(115.34, rel=1e-4)
    assert train.davis.c_n_s2_per_m2 == pytest.approx(13.957, rel=1e-4)
    # about 111 kN at 300 km/h
    assert train.davis.force(units.kmh_to_mps(300.0)) == pytest.approx(111e3, rel=0.01)
    assert train.traction.max_traction_power_w == 20.44e6


def test_mao_2017_preset_has_four_motors_and_mode_1_resistance():
    train = train_preset('mao_2017_500t')
    assert train.mass_kg == 500e3
    assert train.actuator_names == ('motor_1', 'motor_2', 'motor_3', 'motor_4')
    assert train.davis.a_n == pytest.approx(2250.0)
    assert train.davis.b_n_s_per_m == pytest.approx(-6.84)
    assert train.davis.c_n_s2_per_m2 == pytest.approx(4.147, rel=1e-3)
    # about 30 kN at 300 km/h in open air (docs/papers/mao_2017.md)
    assert train.davis.force(units.kmh_to_mps(300.0)) == pytest.approx(30.5e3, rel=0.02)


def test_every_preset_documents_its_sources_and_has_consistent_limits():
    for name in TRAIN_PRESETS:
        train = train_preset(name)
        assert train.sources, name
        t = train.traction
        assert 0 < t.max_service_brake_force_n < t.max_emergency_brake_force_n, name
        assert t.max_traction_force_n > 0 and t.max_traction_power_w > 0, name
        # the train can climb its own starting effort: force above resistance at low speed
        assert t.max_traction_at(10.0) > train.davis.force(10.0), name


@pytest.mark.parametrize('name', sorted(TRAIN_PRESETS))
def test_every_preset_cites_its_design_maximum_speed(name):
    """``TrainParameters.max_speed_mps`` bounds every limit the supervision applies: a preset
    states it (finite) and says where it comes from, as docs/extending.md asks."""
    train = train_preset(name)
    assert math.isfinite(train.max_speed_mps) and train.max_speed_mps > 0.0
    assert train.sources.get('max_speed_mps', '').strip(), (
        f"{name}: sources['max_speed_mps'] must say where the design maximum speed comes from")
