"""The curve plot (``make curves``): the arrays it draws and the PNG it writes."""

import numpy as np

from ato_common.scenario import load_scenario
from profile_node.curves import curve_data, main
from profile_node.planner import plan_reference


def test_the_plotted_arrays_are_the_plan_and_its_supervision():
    scenario = load_scenario('short_line')
    plan = plan_reference(scenario)
    data = curve_data(scenario, plan, step_s=5.0)
    assert np.all(data['speed_mps'] <= data['permitted_at_target_mps'] + 1e-6)
    finite = ~np.isnan(data['curve_position_m'])
    for name in ('ebi', 'sbd', 'permitted', 'indication'):
        values = data[f'{name}_mps'][finite]
        assert np.all(np.nan_to_num(values, nan=np.inf) >= 0.0)
    ordered = [np.nan_to_num(data[f'{n}_mps'][finite], nan=1e9)
               for n in ('ebi', 'permitted', 'indication')]
    assert np.all(ordered[0] >= ordered[1] - 1e-9) and np.all(ordered[1] >= ordered[2] - 1e-9)
    assert np.all(data['permitted_mps'][finite] <= data['mrsp_mps'][finite] + 1e-9)


def test_one_command_writes_one_png_per_scenario(tmp_path, capsys):
    assert main(['short_line', '-o', str(tmp_path)]) == 0
    png = tmp_path / 'short_line.png'
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000
    assert main([str(tmp_path / 'missing.yaml'), '-o', str(tmp_path)]) == 2
    assert 'neither a built-in scenario' in capsys.readouterr().err
