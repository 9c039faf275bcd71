"""Uncertainty of a campaign: how the plant's truth differs from the controller's knowledge.

The controller keeps the nominal train (``knowledge_of(scenario)``, :mod:`ato_common.knowledge`);
the plant runs :func:`perturbed` ``(scenario, draw)``: the nominal scenario with a draw of the
uncertain parameters applied to its train and its ``plant:`` section. The knowledge is never
built from the perturbed scenario, so no drawn value of the truth reaches the controller. One
parameter acts on the knowledge instead (``acts_on='knowledge'``): ``gradient_known`` 0 hides
the line's gradient profile from the controller (``knowledge_options`` gives the arguments of
``knowledge_of``) while the plant keeps its grades; it never changes the plant.

An ``uncertainty:`` specification maps parameter names (:data:`PARAMETERS`) to distributions::

    uncertainty:
      defaults: true            # start from DEFAULTS (false: every parameter at its nominal value)
      mass_factor: {dist: truncated_normal, mean: 1.05, std: 0.04, low: 0.97, high: 1.2}
      wind_mps: {dist: normal, mean: 0.0, std: 3.0}
      adhesion: {dist: choice, values: [0.3, 0.15], weights: [0.8, 0.2]}
      davis_c_factor: 1.1       # a number: that value in every draw
      gradient_known: false     # the controller's knowledge has a flat line (default: true)

Distributions: ``uniform`` (low, high), ``normal`` (mean, std), ``truncated_normal`` (mean,
std, low, high), ``lognormal`` (median, sigma: the standard deviation of the logarithm),
``choice`` (values, optional weights). A draw is a pure function of (campaign seed, draw index,
parameter name): each parameter has its own random stream ``numpy.random.default_rng([seed,
index, crc32(name)])``, so the same draw index gives the same plant to every law (common random
numbers: differences between laws are paired) and overriding one parameter leaves the others'
values as they were.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from statistics import NormalDist
from typing import Any, Mapping

import numpy as np

from ato_common import units
from ato_common.plant_setup import ActuatorFailure, Disturbance, QuantitySensor
from ato_common.trains import DavisResistance
from ato_common.validation import ConfigError, Fields, as_number

DISTRIBUTIONS = ('uniform', 'normal', 'truncated_normal', 'lognormal', 'choice')


@dataclass(frozen=True)
class Distribution:
    """One uncertain parameter's distribution; ``fixed`` (dist 'fixed'): always ``value``."""

    dist: str
    a: float = 0.0                      # uniform: low; normal, truncated: mean; lognormal: median
    b: float = 0.0                      # uniform: high; normal, truncated: std; lognormal: sigma
    low: float = -math.inf
    high: float = math.inf
    values: tuple[float, ...] = ()
    weights: tuple[float, ...] = ()

    def sample(self, rng: np.random.Generator) -> float:
        if self.dist == 'fixed':
            return self.a
        if self.dist == 'uniform':
            return float(rng.uniform(self.a, self.b))
        if self.dist == 'normal':
            return float(rng.normal(self.a, self.b))
        if self.dist == 'truncated_normal':
            normal = NormalDist(self.a, self.b)  # inverse CDF over the kept interval
            u = rng.uniform(normal.cdf(self.low), normal.cdf(self.high))
            return min(max(normal.inv_cdf(min(max(u, 1e-300), 1.0 - 1e-16)), self.low),
                       self.high)
        if self.dist == 'lognormal':
            return float(self.a * math.exp(rng.normal(0.0, self.b)))
        weights = np.asarray(self.weights or [1.0] * len(self.values), dtype=float)
        return float(self.values[int(rng.choice(len(self.values), p=weights / weights.sum()))])

    @property
    def smallest(self) -> float:
        """The smallest value a draw can take (-inf for a normal distribution)."""
        if self.dist in ('fixed', 'uniform'):
            return self.a
        if self.dist == 'truncated_normal':
            return self.low
        if self.dist == 'choice':
            return min(self.values)
        return -math.inf if self.dist == 'normal' else 0.0

    def describe(self) -> str:
        if self.dist == 'fixed':
            return f'{self.a:g}'
        if self.dist == 'uniform':
            return f'uniform [{self.a:g}, {self.b:g}]'
        if self.dist == 'normal':
            return f'normal (mean {self.a:g}, std {self.b:g})'
        if self.dist == 'truncated_normal':
            return (f'normal (mean {self.a:g}, std {self.b:g}) truncated to '
                    f'[{self.low:g}, {self.high:g}]')
        if self.dist == 'lognormal':
            return f'log-normal (median {self.a:g}, sigma of the log {self.b:g})'
        weights = f', weights {list(self.weights)}' if self.weights else ''
        return f'choice of {list(self.values)}{weights}'


@dataclass(frozen=True)
class Parameter:
    """An uncertain parameter: its unit, its nominal value (the controller's), its valid range,
    its default distribution and where that default comes from."""

    name: str
    unit: str
    nominal: float
    minimum: float
    maximum: float
    default: Distribution
    description: str
    source: str
    #: 'plant': the draw changes the truth (perturbed); 'knowledge': it changes what the
    #: controller is told (knowledge_options), never the plant
    acts_on: str = 'plant'
    #: the only values the parameter takes (empty: any in [minimum, maximum])
    allowed: tuple[float, ...] = ()


def _fixed(value: float) -> Distribution:
    return Distribution('fixed', value)


#: every uncertain parameter, with its default distribution and the source of that default
PARAMETERS: dict[str, Parameter] = {p.name: p for p in (
    Parameter('mass_factor', '1', 1.0, 0.5, 2.0,
              Distribution('truncated_normal', 1.05, 0.05, 0.97, 1.20),
              'passenger load: the true mass over the nominal (tare plus normal payload); '
              'scales the train mass and the mass-proportional resistance terms a and b',
              'EN 15663:2017 vehicle reference masses: design mass in working order to '
              'exceptional payload (4 passengers/m^2 standing at 80 kg) is about +15 to +20 % '
              'on a high-speed EMU; the default centres on a light-to-normal load'),
    Parameter('rotating_mass_factor', '1', 0.06, 0.0, 0.3,
              Distribution('uniform', 0.04, 0.10),
              'rotating-mass allowance gamma of the equivalent mass M (1 + gamma): the true '
              'equivalent mass is the nominal times (1 + gamma) / (1 + 0.06)',
              'Bruenger & Dahlhaus, Running time estimation, in Hansen & Pachl (eds.), Railway '
              'Timetabling & Operations (2014): 4-10 % for multiple units, 6 % a common '
              'planning value'),
    Parameter('davis_a_factor', '1', 1.0, 0.3, 3.0,
              Distribution('truncated_normal', 1.0, 0.10, 0.7, 1.3),
              'true Davis a (constant term) over the nominal',
              'Rochard & Schmid, A review of methods to measure and calculate train '
              'resistances, Proc. IMechE F 214 (2000): fitted coefficients of one train '
              'scatter by about 10-20 % between coast-down tests'),
    Parameter('davis_b_factor', '1', 1.0, 0.3, 3.0,
              Distribution('truncated_normal', 1.0, 0.15, 0.6, 1.4),
              'true Davis b (linear term) over the nominal; the least well determined term',
              'Rochard & Schmid (2000), as for davis_a_factor'),
    Parameter('davis_c_factor', '1', 1.0, 0.3, 3.0,
              Distribution('truncated_normal', 1.0, 0.08, 0.8, 1.2),
              'true Davis c (aerodynamic term) over the nominal (track, tunnel and formation '
              'effects)',
              'Rochard & Schmid (2000); EN 14067-4:2013 (aerodynamic resistance in open air)'),
    Parameter('wind_mps', 'm/s', 0.0, -25.0, 25.0,
              Distribution('truncated_normal', 0.0, 3.0, -10.0, 10.0),
              'along-track wind, positive a head wind: the aerodynamic term becomes '
              'c (v + w)^2, i.e. a + c w^2 and b + 2 c w',
              'Beaufort 5 (8-10.7 m/s) bounds; mean surface winds of 2-5 m/s (WMO No. 8, '
              'Guide to Meteorological Instruments, 2018)'),
    Parameter('actuator_time_constant_s', 's', 0.0, 0.0, 10.0,
              Distribution('uniform', 0.2, 1.0),
              'first-order lag of traction and brake force (plant.actuators.time_constant_s)',
              'EN 14531-1:2015 brake build-up times (service brake 2-4 s to 95 %, a time '
              'constant near 1 s); traction drives respond in a few hundred ms'),
    Parameter('actuator_dead_time_s', 's', 0.0, 0.0, 5.0,
              Distribution('uniform', 0.1, 0.5),
              'dead time of traction and brake force before the lag acts '
              '(plant.actuators.dead_time_s): a drive responds to what it was asked that long '
              'ago',
              'UIC 544-1 (2014) equivalent response time of the brake (the delay before the '
              'force builds up is a few tenths of a second on an electro-pneumatic EMU brake); '
              'traction converters and the train bus add about 0.1 s (suite assumption within '
              'those figures)'),
    Parameter('traction_effectiveness', '1', 1.0, 0.05, 1.0,
              Distribution('choice', values=(1.0, 0.875), weights=(0.9, 0.1)),
              'traction effectiveness: every actuator delivers this share of its healthy '
              'traction force for the whole run (a partial loss, plant.failures kind partial '
              'traction_effectiveness); braking is not affected',
              'suite assumption: the loss of one traction converter of 8 on an EMU removes '
              '12.5 % of the traction effort (its electric brake is made up for by the '
              'friction brake); the default has it in one draw of 10'),
    Parameter('brake_effectiveness', '1', 1.0, 0.05, 1.0,
              Distribution('choice', values=(1.0, 0.9375), weights=(0.95, 0.05)),
              'brake effectiveness: every actuator delivers this share of its healthy braking '
              'force for the whole run (a partial loss, plant.failures kind partial '
              'brake_effectiveness); traction is not affected',
              'suite assumption: the friction brake of one bogie of 16 isolated (cut out) on '
              'an 8-car EMU removes 1/16 of the braking effort; the default has it in one '
              'draw of 20'),
    Parameter('adhesion', '1', 0.3, 0.02, 0.5,
              Distribution('choice', values=(0.30, 0.15), weights=(0.8, 0.2)),
              'wheel-rail adhesion coefficient mu: caps the true traction and brake force at '
              'mu M g (dry rail 0.3, wet 0.15); the truth of the run, not the braking '
              "model's design bound (trains.ADHESION_COEFFICIENT, dry 0.15 / wet 0.10)",
              'EN 15595:2018 (wheel slide protection): dry rail 0.25-0.35, wet 0.1-0.2, low '
              'adhesion below 0.05; the default is dry with a 20 % chance of wet rail'),
    Parameter('speed_noise_mps', 'm/s', 0.0, 0.0, 2.0,
              Distribution('uniform', 0.0, 0.05),
              'standard deviation of the white noise of the measured speed',
              'UNISIG SUBSET-041 5.3.1.2 (ETCS speed accuracy +/-2 km/h at low speed): '
              'an odometer inside that band has a noise of a few cm/s'),
    Parameter('speed_bias_mps', 'm/s', 0.0, -2.0, 2.0,
              Distribution('truncated_normal', 0.0, 0.05, -0.2, 0.2),
              'bias of the measured speed, in full from 30 km/h and in proportion to the speed '
              'below (plant_setup.speed_reading: a moving train never reads as standing or '
              'running backwards); its integral errs the measured position until the next '
              'balise group of the line',
              'UNISIG SUBSET-041 5.3.1.2, as for speed_noise_mps'),
    Parameter('position_bias_m', 'm', 0.0, -50.0, 50.0,
              Distribution('truncated_normal', 0.0, 0.5, -2.0, 2.0),
              'error of the position the train starts its mission with: the measured position '
              'and the ATP odometry err by it until the first balise group of the line, which '
              'corrects it (a relocation)',
              'UNISIG SUBSET-041 5.3.1.1: odometry distance error +/-(5 m + 5 % of the '
              'distance since the last balise); the default is a start position known to a '
              'few metres (a train that starts on its stored position)'),
    Parameter('odometry_scale_error', '1', 0.0, -0.1, 0.1,
              Distribution('truncated_normal', 0.0, 0.001, -0.005, 0.005),
              'relative scale error s of the odometer (a wheel diameter known as D while it is '
              'D (1 + s)): the measured speed is (1 + s) v and the measured position errs by s '
              'times the distance since the last balise group of the line (the default '
              'placement of line.default_balise_groups, or the groups the scenario declares; '
              'plant.sensors.*.scale_error)',
              'EN 15313:2016 wheel wear: a 920 mm wheel may wear to about 850 mm, 8 %, which '
              'the odometer corrects by calibrating the diameter against balise distances; '
              'the default residual, within +/-0.5 % (SUBSET-041 5.3.1.2 speed accuracy), is a '
              'suite assumption'),
    Parameter('disturbance_per_weight', '1', 0.0, 0.0, 0.05,
              Distribution('uniform', 0.0, 0.002),
              'amplitude of a random external force (plant.disturbance kind random, a new '
              'value every 5 s) over the train weight M g: 0.002 is a 2 per mille grade',
              'suite assumption: unmodelled grades, gusts and coupler forces of the order of a '
              'per mille of the weight'),
    Parameter('gradient_known', '1', 1.0, 0.0, 1.0, _fixed(1.0),
              'the controller knows the line\'s gradient profile (1, or true) or not (0, or '
              'false: its knowledge is a flat line, so a law that feeds the grade force '
              'forward gets zero grade); the plant runs the true grades either way. Acts on '
              'the knowledge (knowledge_of(scenario, hide_gradient=True)), not the plant',
              'UNISIG SUBSET-026 packet 21: ETCS gives the train the gradient profile ahead; '
              'hiding it stands for track data that is missing or not used (the default: '
              'known in every draw)',
              acts_on='knowledge', allowed=(0.0, 1.0)),
)}

#: parameters that no longer exist, with what replaced them (an old file is refused with it)
RENAMED = {
    'effectiveness': 'replaced by traction_effectiveness and brake_effectiveness (a lost '
                     'traction converter does not lose the friction brake); give either or '
                     'both, e.g. traction_effectiveness: {dist: choice, values: [1.0, 0.875]}',
}
#: the nominal draw: every parameter at the controller's value (the plant is its model)
NOMINAL = {name: _fixed(p.nominal) for name, p in PARAMETERS.items()}
#: the default uncertainty of a campaign
DEFAULTS = {name: p.default for name, p in PARAMETERS.items()}
#: hold time of the random disturbance, s
DISTURBANCE_HOLD_S = 5.0


def _distribution(value: Any, where: str, param: Parameter) -> Distribution:
    distribution = _any_distribution(value, where, param)
    if param.allowed:
        values = (distribution.a,) if distribution.dist == 'fixed' else \
            distribution.values if distribution.dist == 'choice' else None
        valid = ', '.join(f'{v:g}' for v in param.allowed)
        if values is None:
            raise ConfigError(f'{where}: takes only the values {valid}: a number or '
                              f'{{dist: choice, values: [...]}}, not {distribution.dist}')
        for v in values:
            if v not in param.allowed:
                raise ConfigError(f'{where}: {v:g} is not one of its values ({valid})')
    return distribution


def _any_distribution(value: Any, where: str, param: Parameter) -> Distribution:
    if isinstance(value, bool) and param.allowed == (0.0, 1.0):
        value = float(value)  # a yes/no parameter: true is 1, false 0
    number = as_number(value)
    if number is not None:
        if not (math.isfinite(number) and param.minimum <= number <= param.maximum):
            raise ConfigError(f'{where}: must be a finite number in [{param.minimum:g}, '
                              f'{param.maximum:g}] {param.unit}, got {value!r}')
        return _fixed(number)
    f = Fields(value, where)
    dist = f.text('dist')
    if dist not in DISTRIBUTIONS:
        raise ConfigError(f"{where}.dist: '{dist}' is not valid; valid: "
                          f"{', '.join(DISTRIBUTIONS)}")
    lo, hi = param.minimum, param.maximum

    def bounded(key: str) -> float:
        return f.number(key, minimum=lo, maximum=hi)

    if dist == 'uniform':
        a, b = bounded('low'), bounded('high')
        if not b > a:
            raise ConfigError(f'{where}: high ({b:g}) must be above low ({a:g})')
        d = Distribution(dist, a, b)
    elif dist == 'normal':
        d = Distribution(dist, bounded('mean'), f.number('std', minimum=0.0))
        # an unbounded normal can leave the parameter's valid range: it must stay 6 std inside
        if d.a - 6 * d.b < lo or d.a + 6 * d.b > hi:
            raise ConfigError(f'{where}: mean +/- 6 std leaves the valid range [{lo:g}, {hi:g}] '
                              f'{param.unit}; use truncated_normal')
    elif dist == 'truncated_normal':
        d = Distribution(dist, f.number('mean'), f.number('std', minimum=0.0,
                                                          exclusive_minimum=True),
                         bounded('low'), bounded('high'))
        if not d.high > d.low:
            raise ConfigError(f'{where}: high ({d.high:g}) must be above low ({d.low:g})')
        if not d.low <= d.a <= d.high:  # its draws would pile up at one bound
            raise ConfigError(f'{where}.mean: {d.a:g} must lie within [low, high] = '
                              f'[{d.low:g}, {d.high:g}]')
    elif dist == 'lognormal':
        d = Distribution(dist, f.number('median', minimum=0.0, exclusive_minimum=True),
                         f.number('sigma', minimum=0.0, maximum=2.0))
        if d.a * math.exp(-6 * d.b) < lo or d.a * math.exp(6 * d.b) > hi:
            raise ConfigError(f'{where}: median exp(+/-6 sigma) leaves the valid range '
                              f'[{lo:g}, {hi:g}] {param.unit}')
    else:
        values = f.raw('values')
        if not isinstance(values, list) or not values:
            raise ConfigError(f'{where}.values: must be a non-empty list of numbers')
        checked = []
        for i, v in enumerate(values):
            n = as_number(float(v) if isinstance(v, bool) and param.allowed == (0.0, 1.0)
                          else v)
            if n is None or not (math.isfinite(n) and lo <= n <= hi):
                raise ConfigError(f'{where}.values[{i}]: must be a number in [{lo:g}, {hi:g}] '
                                  f'{param.unit}, got {v!r}')
            checked.append(n)
        weights = f.raw('weights') or []
        if weights:
            ws = [as_number(w) for w in weights] if isinstance(weights, list) else [None]
            numbers = [w for w in ws if w is not None and w >= 0]
            if len(ws) != len(checked) or len(numbers) != len(ws) or not sum(numbers) > 0:
                raise ConfigError(f'{where}.weights: must be {len(checked)} numbers >= 0 with '
                                  'a positive sum')
            weights = numbers
        d = Distribution(dist, values=tuple(checked), weights=tuple(weights))
    f.reject_unknown()
    return d


def parse_uncertainty(data: Any, where: str = 'uncertainty') -> dict[str, Distribution]:
    """The distributions of every parameter: ``data`` None or 'nominal' gives NOMINAL,
    'default' gives DEFAULTS, a mapping overrides DEFAULTS (or NOMINAL with ``defaults:
    false``). ConfigError names the field for an unknown parameter or an invalid
    distribution."""
    if data is None or data == 'nominal':
        return dict(NOMINAL)
    if data == 'default':
        return dict(DEFAULTS)
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where}: must be 'default', 'nominal' or a mapping of parameters, "
                          f'got {data!r}')
    base = data.get('defaults', True)
    if not isinstance(base, bool):
        raise ConfigError(f'{where}.defaults: must be true or false, got {base!r}')
    spec = dict(DEFAULTS if base else NOMINAL)
    for key, value in data.items():
        if key == 'defaults':
            continue
        if key in RENAMED:
            raise ConfigError(f'{where}.{key}: {RENAMED[key]}')
        if key not in PARAMETERS:
            raise ConfigError(f"{where}.{key}: unknown parameter; valid: "
                              f"{', '.join(PARAMETERS)}")
        spec[key] = _distribution(value, f'{where}.{key}', PARAMETERS[key])
    return spec


def draw(spec: Mapping[str, Distribution], seed: int, index: int) -> dict[str, float]:
    """The values of draw ``index`` of a campaign seeded ``seed``: the same for every law."""
    return {name: spec[name].sample(np.random.default_rng(
        [seed, index, zlib.crc32(name.encode())])) for name in PARAMETERS}


def _davis(davis: DavisResistance, load: float, values: Mapping[str, float]) -> DavisResistance:
    a = davis.a_n * load * values['davis_a_factor']
    b = davis.b_n_s_per_m * load * values['davis_b_factor']
    c = davis.c_n_s2_per_m2 * values['davis_c_factor']
    w = values['wind_mps']
    return DavisResistance(a + c * w * w, b + 2.0 * c * w, c)


#: the parameters that act on the plant's truth, and those that act on the knowledge
PLANT_PARAMETERS = tuple(n for n, p in PARAMETERS.items() if p.acts_on == 'plant')
KNOWLEDGE_PARAMETERS = tuple(n for n, p in PARAMETERS.items() if p.acts_on == 'knowledge')


def knowledge_options(values: Mapping[str, float] | None) -> dict[str, Any]:
    """What a draw changes in what the controller is told: the keyword arguments of
    ``ato_common.knowledge.knowledge_of`` (``hide_gradient``). Only the knowledge parameters
    (KNOWLEDGE_PARAMETERS) are read; no value of the plant's truth reaches the controller."""
    known = 1.0 if values is None else values.get('gradient_known', 1.0)
    return {'hide_gradient': known == 0.0}


def perturbed(scenario, values: Mapping[str, float]):
    """The plant's truth for one draw: ``scenario`` (the nominal, which the controller keeps)
    with the drawn ``values`` of the plant parameters (PLANT_PARAMETERS) applied to its train
    and its ``plant:`` section. The knowledge parameters are not read: the plant of a draw is
    the same whatever the controller is told (its noise and disturbance seeds too), so two
    runs that differ only in what the controller knows are paired."""
    v = {name: values[name] for name in PLANT_PARAMETERS}
    if all(v[name] == PARAMETERS[name].nominal for name in PLANT_PARAMETERS):
        return scenario
    train, plant = scenario.train, scenario.plant
    load = v['mass_factor']
    inertia = load * (1.0 + v['rotating_mass_factor']) / (1.0 + PARAMETERS[
        'rotating_mass_factor'].nominal)
    mass = train.mass_kg * inertia
    cars = tuple(replace(car, mass_kg=car.mass_kg * inertia,
                         a_mps2=car.a_mps2 * load / inertia * v['davis_a_factor'],
                         b_per_s=car.b_per_s * load / inertia * v['davis_b_factor'],
                         c_per_m=car.c_per_m / inertia * v['davis_c_factor'])
                 for car in train.cars)
    if cars and v['wind_mps']:
        lead, w = cars[0], v['wind_mps']
        cars = (replace(lead, a_mps2=lead.a_mps2 + lead.c_per_m * w * w,
                        b_per_s=lead.b_per_s + 2.0 * lead.c_per_m * w),) + cars[1:]
    limit = v['adhesion'] * train.mass_kg * load * units.STANDARD_GRAVITY
    t = train.traction
    traction = replace(t, max_traction_force_n=min(t.max_traction_force_n, limit),
                       max_service_brake_force_n=min(t.max_service_brake_force_n, limit),
                       max_emergency_brake_force_n=min(t.max_emergency_brake_force_n, limit))
    true_train = replace(train, mass_kg=mass, davis=_davis(train.davis, load, v), cars=cars,
                         traction=traction)
    modes = tuple(replace(m, mass_kg=m.mass_kg * inertia, davis=_davis(m.davis, load, v))
                  for m in plant.modes)
    actuators = replace(plant.actuators, time_constant_s=max(
        plant.actuators.time_constant_s, v['actuator_time_constant_s']),
        dead_time_s=max(plant.actuators.dead_time_s, v['actuator_dead_time_s']))
    failures = plant.failures
    traction_share, brake_share = v['traction_effectiveness'], v['brake_effectiveness']
    if traction_share < 1.0 or brake_share < 1.0:
        failed = {f.actuator for f in failures if f.start_s <= 0.0}
        failures = failures + tuple(
            ActuatorFailure(name, 'partial', 0.0, min((f.start_s for f in failures
                                                       if f.actuator == name), default=math.inf),
                            effectiveness=traction_share, brake_effectiveness=brake_share)
            for name in train.actuator_names if name not in failed)
    disturbance = plant.disturbance
    if v['disturbance_per_weight'] > 0.0 and disturbance.kind == 'none':
        disturbance = Disturbance('random', v['disturbance_per_weight'] * mass
                                  * units.STANDARD_GRAVITY, hold_s=DISTURBANCE_HOLD_S,
                                  seed=zlib.crc32(repr(sorted(v.items())).encode()) % 2**31)
    s = plant.sensors
    scale = v['odometry_scale_error']
    speed = _add_error(s.speed, v['speed_noise_mps'], v['speed_bias_mps'], scale)
    position = _add_error(s.position, 0.0, v['position_bias_m'], scale)
    sensors = replace(s, speed=speed, position=position,
                      seed=(s.seed + zlib.crc32(repr(sorted(v.items())).encode())) % 2**31)
    true_plant = replace(plant, modes=modes, actuators=actuators, failures=failures,
                         disturbance=disturbance, sensors=sensors)
    true_plant.__dict__.pop('mode_schedule', None)  # a cached lookup of the copied modes
    return replace(scenario, train=true_train, plant=true_plant)


def _add_error(sensor: QuantitySensor, noise_std: float, bias: float,
               scale_error: float = 0.0) -> QuantitySensor:
    if noise_std == 0.0 and bias == 0.0 and scale_error == 0.0:
        return sensor
    # two scale errors compose: (1 + s1)(1 + s2) - 1
    return replace(sensor, noise_std=math.hypot(sensor.noise_std, noise_std),
                   bias=sensor.bias + bias,
                   scale_error=(1.0 + sensor.scale_error) * (1.0 + scale_error) - 1.0)


def describe(spec: Mapping[str, Distribution]) -> list[tuple[str, str, str, str]]:
    """(parameter, unit, distribution, source) rows of a specification, for reports."""
    return [(name, p.unit, spec[name].describe(), p.source) for name, p in PARAMETERS.items()]
