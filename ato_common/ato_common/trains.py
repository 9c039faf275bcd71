"""Train parameter sets in SI units, each a named preset with its source.

A preset carries two resistance laws: ``davis`` is what the plant simulates (the "true" train) and
``davis_nominal`` is the prior that on-board software knows (a paper's nominal table). Conversions
from the papers' units happen here, through :mod:`ato_common.units`, and nowhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from ato_common import units


@dataclass(frozen=True)
class DavisResistance:
    """Running resistance R(v) = a + b v + c v^2 of the whole train, in N (v in m/s)."""

    a_n: float
    b_n_s_per_m: float
    c_n_s2_per_m2: float

    def force(self, speed: float) -> float:
        """Resistance in N; it opposes motion, so it is applied with the sign of the speed."""
        v = abs(speed)
        return self.a_n + self.b_n_s_per_m * v + self.c_n_s2_per_m2 * v * v

    @classmethod
    def from_per_tonne(cls, mass_kg: float, a_n_per_t: float, b_n_per_t_kmh: float,
                       c_n_per_t_kmh2: float) -> 'DavisResistance':
        a, b, c = units.davis_per_tonne_to_per_kg(a_n_per_t, b_n_per_t_kmh, c_n_per_t_kmh2)
        return cls(a * mass_kg, b * mass_kg, c * mass_kg)

    @classmethod
    def from_kn_kmh(cls, a_kn: float, b_kn_per_kmh: float, c_kn_per_kmh2: float
                    ) -> 'DavisResistance':
        """Whole-train coefficients in kN with V in km/h (Mao et al. 2017, reading (A))."""
        return cls(*units.davis_kn_kmh_to_n(a_kn, b_kn_per_kmh, c_kn_per_kmh2))

    def per_kg(self, mass_kg: float) -> tuple[float, float, float]:
        """(a [m/s^2], b [1/s], c [1/m]): the specific resistance of the papers' laws."""
        return (self.a_n / mass_kg, self.b_n_s_per_m / mass_kg, self.c_n_s2_per_m2 / mass_kg)


@dataclass(frozen=True)
class TractionCharacteristic:
    """What the drive and brakes can deliver, for the whole train.

    Maximum tractive effort is the lower of the starting effort and the power hyperbola P/v;
    braking is limited by a force (service braking, the limit an ATO may use).
    """

    max_traction_force_n: float
    max_traction_power_w: float
    max_service_brake_force_n: float
    max_emergency_brake_force_n: float

    def max_traction_at(self, speed: float) -> float:
        v = abs(speed)
        if v <= 0.0:
            return self.max_traction_force_n
        return min(self.max_traction_force_n, self.max_traction_power_w / v)

    def limits_at(self, speed: float) -> tuple[float, float]:
        """(lowest, highest) total force an ATO may command at this speed, N."""
        return (-self.max_service_brake_force_n, self.max_traction_at(speed))


# Wheel-rail adhesion available to the brakes, by rail condition: the braking force of a train
# whose axles all brake cannot exceed mu m g (m its static mass, without rotating masses). Dry:
# 0.15, the adhesion a brake design may demand at most in European practice (EN 14531-1 and the
# TSI LOC&PAS compute brake performance with no more than 0.15); wet: 0.10, the lower end of the
# 0.10-0.20 usually found on a wet rail (lower, contaminated rails, the autumn case, are not
# modelled). docs/guide/plant.md gives the bound and where it applies. These are what a brake
# design may count on (the braking model's bound, known on board); the adhesion the rail actually
# offers in a run is the plant's truth, drawn by a campaign (``ato_common.uncertainty``'s
# ``adhesion``, dry 0.30 / wet 0.15 after EN 15595), and is higher by design margin.
ADHESION_COEFFICIENT = {'dry': 0.15, 'wet': 0.10}
RAIL_CONDITIONS = tuple(ADHESION_COEFFICIENT)


def adhesion_braking_limit_n(static_mass_kg: float, rail: str = 'dry',
                             gravity: float = units.STANDARD_GRAVITY) -> float:
    """The most braking force the wheel-rail contact transmits: mu(rail) m g, N."""
    if rail not in ADHESION_COEFFICIENT:
        raise ValueError(f'unknown rail condition {rail!r}; valid: {", ".join(RAIL_CONDITIONS)}')
    return ADHESION_COEFFICIENT[rail] * static_mass_kg * gravity


@dataclass(frozen=True)
class BoundedBraking:
    """A train's braking capability after the physical bounds, and what each bound changed."""

    traction: TractionCharacteristic
    adhesion_limit_n: float
    notes: tuple[str, ...]   # one per figure a bound lowered, naming the figure and the bound


def bound_braking(traction: TractionCharacteristic, static_mass_kg: float, rail: str = 'dry',
                  service_limit_n: float | None = None, emergency_limit_n: float | None = None,
                  names: Mapping[str, str] | None = None) -> BoundedBraking:
    """The service and emergency brake forces bounded by adhesion (``adhesion_braking_limit_n``)
    and by the data's own limits where it has them (``service_limit_n``,
    ``emergency_limit_n``: an ETCS deceleration times the equivalent mass); the emergency brake
    is then never below the service brake. ``names`` names the two figures as the data does
    (default: the field names)."""
    names = {'service': 'max_service_brake_force_n', 'emergency': 'max_emergency_brake_force_n',
             **(names or {})}
    adhesion = adhesion_braking_limit_n(static_mass_kg, rail)
    adhesion_text = (f'the wheel-rail adhesion bound {adhesion / 1000.0:.1f} kN (mu '
                     f'{ADHESION_COEFFICIENT[rail]:g} on a {rail} rail x '
                     f'{static_mass_kg / 1000.0:g} t x g)')
    notes = []

    def bounded(kind: str, force: float, data_limit: float | None, data_text: str) -> float:
        exceeded = [text for limit, text in ((adhesion, adhesion_text), (data_limit, data_text))
                    if limit is not None and force > limit]
        if not exceeded:
            return force
        result = min(limit for limit in (adhesion, data_limit) if limit is not None)
        notes.append(f'{names[kind]} {force / 1000.0:.1f} kN exceeds {" and ".join(exceeded)}; '
                     f'bounded to {result / 1000.0:.1f} kN')
        return result

    service = bounded('service', traction.max_service_brake_force_n, service_limit_n,
                      'the ETCS service deceleration times the equivalent mass '
                      f'({(service_limit_n or 0.0) / 1000.0:.1f} kN)')
    emergency = bounded('emergency', traction.max_emergency_brake_force_n, emergency_limit_n,
                        'the ETCS emergency deceleration times the equivalent mass '
                        f'({(emergency_limit_n or 0.0) / 1000.0:.1f} kN)')
    return BoundedBraking(
        TractionCharacteristic(traction.max_traction_force_n, traction.max_traction_power_w,
                               service, max(emergency, service)), adhesion, tuple(notes))


@dataclass(frozen=True)
class CarParameters:
    """One car of a multi-car model (Mao, Tao, Jiang & Yan eqs 1-7), SI per kg of the car."""

    name: str
    mass_kg: float
    a_mps2: float        # constant resistance per kg
    b_per_s: float       # speed-proportional resistance per kg
    c_per_m: float = 0.0  # aerodynamic resistance per kg (lead car only in the paper)
    powered: bool = False


@dataclass(frozen=True)
class Coupler:
    """Spring-damper between consecutive cars."""

    stiffness_n_per_m: float
    damping_n_s_per_m: float


@dataclass(frozen=True)
class TrainParameters:
    name: str
    description: str
    mass_kg: float                 # equivalent mass (rotating masses included) that inertia sees
    davis: DavisResistance         # the simulated ("true") running resistance
    davis_nominal: DavisResistance  # the on-board prior
    traction: TractionCharacteristic
    actuator_names: tuple[str, ...] = ('traction',)
    length_m: float = 200.0
    sources: Mapping[str, str] = field(default_factory=dict)
    cars: tuple[CarParameters, ...] = ()      # for multi-car models, lead car first
    couplers: tuple[Coupler, ...] = ()        # len(cars) - 1 of them
    car_length_m: float = 25.0
    # Design maximum speed: bounds every speed limit the supervision applies (a train is never
    # permitted faster, whatever the line allows). Every preset cites it in ``sources``.
    max_speed_mps: float = math.inf
    # The share of the braking work at the wheel the regenerative brake returns, up to its
    # power (ato_common.metrics' regenerated energy; 0: every braking loses its energy, as for
    # the presets, whose papers give none). A TTOBench train gives both.
    regenerative_efficiency: float = 0.0
    regenerative_power_w: float = math.inf


def _crh3_luo_xu() -> TrainParameters:
    mass = units.tonnes_to_kg(510.0)
    return TrainParameters(
        name='crh3_luo_xu',
        description='CRH3 (Velaro CN) 8-car EMU, 510 t, as simulated by Luo & Xu',
        mass_kg=mass,
        # Table 1 (true values), units N/t with V in km/h (see docs/papers/luo_xu.md).
        davis=DavisResistance.from_per_tonne(mass, 7.75, 0.06327, 0.00128),
        # Table 2 (nominal prior), cv corrected from the printed 0.6318 to 0.06318.
        davis_nominal=DavisResistance.from_per_tonne(mass, 7.85, 0.06318, 0.00127),
        traction=TractionCharacteristic(
            max_traction_force_n=units.kn_to_n(300.0),
            max_traction_power_w=units.kw_to_w(8800.0),
            max_service_brake_force_n=mass * 0.9,
            max_emergency_brake_force_n=mass * 1.2,
        ),
        actuator_names=('traction',),
        length_m=200.0,
        max_speed_mps=units.kmh_to_mps(350.0),
        sources={
            'max_speed_mps': 'CRH3C (Velaro CN) design maximum speed 350 km/h '
                             '(manufacturer figure)',
            'mass, davis, davis_nominal': 'Luo & Xu, Tables 1 and 2 (510 t; N/t, V in km/h)',
            'max_traction_force_n, max_traction_power_w':
                'CRH3C (Velaro CN) data sheet figures: starting tractive effort 300 kN, '
                'traction power 8.8 MW',
            'service and emergency braking':
                'suite assumption: 0.9 and 1.2 m/s^2 of the equivalent mass, typical of '
                'high-speed EMU service/emergency brake design values; no paper gives them',
        },
    )


def _crh380a_tan() -> TrainParameters:
    mass = units.tonnes_to_kg(442.0)
    davis = DavisResistance.from_per_tonne(mass, 5.6, 0.036, 0.00121)
    return TrainParameters(
        name='crh380a_tan',
        description='CRH380A(L) 8-car 6M2T, 442 t, as simulated by Tan, Jiang & Chen',
        mass_kg=mass,
        davis=davis,
        davis_nominal=davis,
        traction=TractionCharacteristic(
            max_traction_force_n=mass * 0.6,
            max_traction_power_w=units.kw_to_w(9600.0),
            max_service_brake_force_n=mass * 0.9,
            max_emergency_brake_force_n=mass * 1.2,
        ),
        actuator_names=('traction',),
        length_m=203.0,
        max_speed_mps=units.kmh_to_mps(380.0),
        sources={
            'max_speed_mps': 'CRH380A design maximum operating speed 380 km/h '
                             '(manufacturer figure)',
            'mass, davis': 'Tan, Jiang & Chen, Table 1 (442 t; 5.6 + 0.036 V + 0.00121 V^2 N/t)',
            'max_traction_power_w': 'CRH380A 8-car traction power 9.6 MW (manufacturer figure)',
            'max_traction_force_n': 'suite assumption: 0.6 m/s^2 starting acceleration',
            'service and emergency braking': 'suite assumption: 0.9 and 1.2 m/s^2',
        },
    )


def _four_car_unit(masses_t, a_n_per_t, b_n_per_t_kmh, c_n_per_t_kmh2, couplers):
    """Cars of a Mao, Tao, Jiang & Yan 4-car unit: a, b, c per tonne with V in km/h (the
    printed SI-like units of Tables I and II are a slip: 0.88 + 0.00744 V + 0.000114 V^2 N/kN
    times g gives the CRH2 numbers); power on cars 2 and 3; aerodynamics on the lead car."""
    cars = []
    for i, (m, a, b) in enumerate(zip(masses_t, a_n_per_t, b_n_per_t_kmh)):
        a_si, b_si, c_si = units.davis_per_tonne_to_per_kg(a, b, c_n_per_t_kmh2)
        cars.append(CarParameters(f'car_{i + 1}', units.tonnes_to_kg(m), a_si, b_si,
                                  c_si if i == 0 else 0.0, powered=i in (1, 2)))
    davis = DavisResistance(sum(c.a_mps2 * c.mass_kg for c in cars),
                            sum(c.b_per_s * c.mass_kg for c in cars),
                            cars[0].c_per_m * cars[0].mass_kg)
    return tuple(cars), tuple(Coupler(k, d) for k, d in couplers), davis


def _crh2_4car_mao() -> TrainParameters:
    cars, couplers, davis = _four_car_unit(
        masses_t=(42.8, 48.0, 46.5, 42.0), a_n_per_t=(8.63, 9.03, 9.03, 8.63),
        b_n_per_t_kmh=(0.07295, 0.08015, 0.08015, 0.07295), c_n_per_t_kmh2=0.00112,
        couplers=((800e6, 8e4), (600e6, 6e4), (800e6, 8e4)))
    mass = sum(c.mass_kg for c in cars)
    return TrainParameters(
        name='crh2_4car_mao',
        description='CRH2 4-car unit, power on cars 2 and 3, as simulated by Mao, Tao, Jiang & Yan',
        mass_kg=mass, davis=davis, davis_nominal=davis,
        traction=TractionCharacteristic(
            max_traction_force_n=mass * 0.6, max_traction_power_w=units.kw_to_w(2400.0),
            max_service_brake_force_n=mass * 0.9, max_emergency_brake_force_n=mass * 1.2),
        actuator_names=('car_2', 'car_3'), length_m=100.0, cars=cars,
        couplers=couplers, car_length_m=25.0,
        max_speed_mps=units.kmh_to_mps(250.0),
        sources={
            'max_speed_mps': 'CRH2A design maximum speed 250 km/h (manufacturer figure)',
            'masses, resistance, couplers': 'Mao, Tao, Jiang & Yan, Table II (units corrected '
                                            'as in docs/papers/mao_multibody.md)',
            'max_traction_power_w': 'half of the 4.8 MW of an 8-car CRH2A (two such units)',
            'max_traction_force_n, braking': 'suite assumption: 0.6, 0.9 and 1.2 m/s^2',
        })


def _crh5_4car_mao() -> TrainParameters:
    cars, couplers, davis = _four_car_unit(
        masses_t=(50.0, 48.0, 51.0, 53.0), a_n_per_t=(6.63, 5.43, 5.43, 6.63),
        b_n_per_t_kmh=(0.06382, 0.07041, 0.07041, 0.06382), c_n_per_t_kmh2=0.00107,
        couplers=((500e6, 2e4), (650e6, 2.2e4), (500e6, 2e4)))
    mass = sum(c.mass_kg for c in cars)
    return TrainParameters(
        name='crh5_4car_mao',
        description='CRH5 4-car unit, power on cars 2 and 3, as in the zero-dynamics study '
                    '(Section IV-D) of Mao, Tao, Jiang & Yan',
        mass_kg=mass, davis=davis, davis_nominal=davis,
        traction=TractionCharacteristic(
            max_traction_force_n=mass * 0.6, max_traction_power_w=units.kw_to_w(2750.0),
            max_service_brake_force_n=mass * 0.9, max_emergency_brake_force_n=mass * 1.2),
        actuator_names=('car_2', 'car_3'), length_m=100.0, cars=cars,
        couplers=couplers, car_length_m=25.0,
        max_speed_mps=units.kmh_to_mps(250.0),
        sources={
            'max_speed_mps': 'CRH5A design maximum speed 250 km/h (manufacturer figure)',
            'masses, resistance, couplers': 'Mao, Tao, Jiang & Yan, Table I (CRH5: 50/48/51/53 t; '
                                            'a 6.63/5.43 N/t, b 0.06382/0.07041 N/(t km/h), '
                                            'c 0.00107 N/(t (km/h)^2), k 500e6/650e6 N/m, '
                                            'd 2e4/2.2e4 N s/m; units corrected as for Table II)',
            'max_traction_power_w': 'half of the 5.5 MW of an 8-car CRH5A (manufacturer figure)',
            'max_traction_force_n, braking': 'suite assumption: 0.6, 0.9 and 1.2 m/s^2',
            'car_length_m': 'not in the paper; only shifts the cars\' rest positions',
        })


def _crh380al_liu_li() -> TrainParameters:
    mass = units.tonnes_to_kg(890.0)
    # Liu & Li's resistance formula (60)-(61) was lost in extraction; docs/papers/liu_li.md
    # takes the CRH380A(L) unit resistance of Tan et al.: a0 = 4984 N, a1 = 115.34 N s/m,
    # a2 = 13.957 N s^2/m^2 for 890 t.
    davis = DavisResistance.from_per_tonne(mass, 5.6, 0.036, 0.00121)
    return TrainParameters(
        name='crh380al_liu_li',
        description='CRH380AL 16-car (14M2T), 890 t, as simulated by Liu & Li',
        mass_kg=mass, davis=davis, davis_nominal=davis,
        traction=TractionCharacteristic(
            max_traction_force_n=units.kn_to_n(500.0),
            max_traction_power_w=units.kw_to_w(20440.0),
            max_service_brake_force_n=mass * 0.9,
            max_emergency_brake_force_n=mass * 1.2),
        actuator_names=('traction',), length_m=399.0,
        max_speed_mps=units.kmh_to_mps(380.0),
        sources={
            'max_speed_mps': 'CRH380AL design maximum operating speed 380 km/h '
                             '(manufacturer figure)',
            'mass': 'Liu & Li, Section 5 (M = 890 t; g = 9.8 m/s^2 in the paper, the suite uses '
                    'standard gravity)',
            'davis': 'Liu & Li formula lost; docs/papers/liu_li.md takes '
                     '5.6 + 0.036 V + 0.00121 V^2 N/t (Tan et al. Table 1) scaled to 890 t',
            'max_traction_power_w': 'CRH380AL traction power 20.44 MW (manufacturer figure)',
            'max_traction_force_n': 'a +/-500 kN actuator limit (docs/papers/liu_li.md; '
                                    'Liu & Li give none)',
            'service and emergency braking': 'suite assumption: 0.9 and 1.2 m/s^2',
            'length_m': 'CRH380AL 16-car length, about 399 m',
        })


def _mao_2017_500t() -> TrainParameters:
    mass = units.tonnes_to_kg(500.0)
    # Mode (i) (open air) of Mao, Tao, Jiang, Yan & Zhong 2017, Section 4.1, read as whole-train
    # coefficients in kN with V in km/h (reading (A) of docs/papers/mao_2017.md):
    # a = 2.25 kN, b = -1.9e-3 kN/(km/h), c = 3.2e-4 kN/(km/h)^2 -> 2250 N, -6.84 N s/m,
    # 4.147 N s^2/m^2. The negative b is the paper's.
    davis = DavisResistance.from_kn_kmh(2.25, -1.9e-3, 3.2e-4)
    return TrainParameters(
        name='mao_2017_500t',
        description='500 t train with 4 motors, as simulated by Mao, Tao, Jiang, Yan & Zhong '
                    '(IFAC 2017); modes, failures: plant section of the scenario',
        mass_kg=mass, davis=davis, davis_nominal=davis,
        traction=TractionCharacteristic(
            max_traction_force_n=units.kn_to_n(300.0),
            max_traction_power_w=units.kw_to_w(8800.0),
            max_service_brake_force_n=mass * 0.9,
            max_emergency_brake_force_n=mass * 1.2),
        actuator_names=('motor_1', 'motor_2', 'motor_3', 'motor_4'), length_m=200.0,
        max_speed_mps=units.kmh_to_mps(350.0),
        sources={
            'max_speed_mps': 'the CRH3C of max_traction_force_n: 350 km/h '
                             '(manufacturer figure)',
            'mass, 4 motors': 'Mao et al. 2017, Section 4 (M = 500 t, n = 4)',
            'davis': 'Mao et al. 2017 mode (i): a = 2.25, b = -1.9e-3, c = 3.2e-4, read as kN '
                     'with V in km/h (reading (A) of docs/papers/mao_2017.md)',
            'max_traction_force_n, max_traction_power_w':
                'the paper borrows "a CRH type train" (Dong et al. 2010); a 500 t CRH with four '
                'motor cars is a CRH3C (4M4T): 300 kN starting effort, 8.8 MW, one quarter per '
                'motor (manufacturer figures)',
            'service and emergency braking': 'suite assumption: 0.9 and 1.2 m/s^2',
        })


TRAIN_PRESETS = {
    'crh3_luo_xu': _crh3_luo_xu,
    'crh380a_tan': _crh380a_tan,
    'crh2_4car_mao': _crh2_4car_mao,
    'crh5_4car_mao': _crh5_4car_mao,
    'crh380al_liu_li': _crh380al_liu_li,
    'mao_2017_500t': _mao_2017_500t,
}


def train_preset(name: str) -> TrainParameters:
    try:
        return TRAIN_PRESETS[name]()
    except KeyError:
        raise KeyError(f"unknown train preset '{name}'; valid: {', '.join(sorted(TRAIN_PRESETS))}"
                       ) from None


def steady_speed(train: TrainParameters, force_n: float, grade_sine: float = 0.0,
                 gravity: float = units.STANDARD_GRAVITY) -> float:
    """Speed at which a constant force balances resistance and grade (nan if none exists)."""
    d = train.davis
    rest = d.a_n + train.mass_kg * gravity * grade_sine - force_n
    disc = d.b_n_s_per_m ** 2 - 4.0 * d.c_n_s2_per_m2 * rest
    if disc < 0.0:
        return math.nan
    return (-d.b_n_s_per_m + math.sqrt(disc)) / (2.0 * d.c_n_s2_per_m2)
