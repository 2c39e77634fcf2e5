# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What the node reports on /diagnostics: the CPU time of its callbacks over one reporting
window (:class:`CallbackLoad`) and its four statuses (:func:`node_statuses`: simulation,
inputs, feedforward, model check), built from the counters of the core's pipeline
(:class:`~worm_gear_sim.realtime.RealtimePredictor`) and of the node.  Keys and levels:
docs/node.md."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from ..realtime import RealtimePredictor
from ..realtime.model_check import ModelCheck
from ..records.topics import COMMAND_TOPIC, REFERENCE_TOPIC
from . import diagnostics as diag
from .interface import NODE_REJECT_REASONS, REJECT_REASONS

__all__ = ['CallbackLoad', 'node_statuses', 'model_check_status', 'backdrive_status',
           'HARDWARE_ID']

HARDWARE_ID = 'worm_gear_sim'

#: the pipeline's counters reported under 'simulation' and 'inputs'
_SIMULATION_COUNTERS = ('predictions', 'steps', 'overruns', 'dropped_time_ns', 'resyncs',
                        'clock_restarts', 'input_switches', 'stale_events', 'stale_retractions',
                        'late_for_simulation',
                        'simulation_errors')
_INPUT_COUNTERS = ('samples_received', 'samples_accepted', 'rejected_samples',
                   *(f'rejected_{r}' for r in REJECT_REASONS),
                   'commands_received', 'commands_used', 'commands_merged',
                   'commands_restamped', 'commands_dropped', 'merged_samples', 'rest_samples',
                   'stream_relocks', 'stream_outliers', 'reconfigurations',
                   'load_samples_received', 'load_samples_accepted', 'rejected_load_samples',
                   *(f'rejected_load_{r}' for r in REJECT_REASONS if r != 'jump'),
                   'late_load_samples')
_PARAMETER_COUNTERS = ('rejected_parameter_sets', 'accepted_parameter_sets',
                       'parameter_build_errors', 'rejected_clock_messages',
                       'loads_beyond_elastic_limit')


class CallbackLoad:
    """CPU time of the node's callbacks (thread time) and the pipeline's progress over one
    reporting window; :meth:`roll` closes the window and opens the next."""

    def __init__(self, rt: RealtimePredictor) -> None:
        self.rt = rt
        self.window = self._start()

    def _start(self) -> dict[str, Any]:
        return dict(wall_ns=time.monotonic_ns(), busy_ns=0, max_busy_ns=0, calls=0, errors=0,
                    sim_t=self.rt.sim.t, steps=self.rt.counters['steps'],
                    predictions=self.rt.counters['predictions'])

    def busy(self, t0: int) -> None:
        """A callback that started at thread time ``t0`` [ns] ends now."""
        busy = time.thread_time_ns() - t0
        w = self.window
        w['busy_ns'] += busy
        w['calls'] += 1
        if busy > w['max_busy_ns']:
            w['max_busy_ns'] = busy

    def error(self) -> None:
        """A simulation error in this window (the status turns ERROR)."""
        self.window['errors'] += 1

    def roll(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """(the window that ends now, the start of the next)."""
        w, self.window = self.window, self._start()
        return w, self.window


def node_statuses(name: str, rt: RealtimePredictor, counters: Mapping[str, Any],
                  load: CallbackLoad, mode: str, command_timing: str,
                  last_error: str) -> list[diag.DiagnosticStatus]:
    """The statuses 'simulation', 'inputs' and 'feedforward' of node ``name`` (closes the
    load window): ``counters`` are the node's own (message rejections, ticks, parameter
    sets), ``mode`` the input path in use ('' before the first input)."""
    w, now = load.roll()
    wall = max(1e-9, (now['wall_ns'] - w['wall_ns']) * 1e-9)
    c, rc = counters, rt.counters
    steps = now['steps'] - w['steps']
    n_pred = now['predictions'] - w['predictions']
    sim = rt.sim
    st = sim.stats
    if not rt.started:
        level, msg = diag.WARN, f'waiting for the first {REFERENCE_TOPIC} or {COMMAND_TOPIC}'
    elif w['errors']:
        level, msg = diag.ERROR, f'{w["errors"]} simulation error(s): {rt.last_error}'
    elif rt.stale:
        level, msg = diag.WARN, ('input stream stale: the reference rests at its last '
                                 'value; publishing the held prediction')
    else:
        level, msg = diag.OK, 'running'
    if c['same_name_nodes'] and level != diag.ERROR:
        level, msg = diag.WARN, (f'{c["same_name_nodes"]} other node(s) with this name on '
                                 'the domain: their topics and parameters mix with ours')
    sim_vals = {
        'input': mode or 'none', 'time_base': 'sim' if rt.sim_time else 'wall',
        'simulated_time_s': sim.t, 'stale': rt.stale,
        'real_time_factor': (now['sim_t'] - w['sim_t']) / wall,
        'steps_per_prediction': steps / n_pred if n_pred else 0.0,
        'compute_load': w['busy_ns'] * 1e-9 / wall,
        'max_callback_cpu_ms': w['max_busy_ns'] * 1e-6, 'callbacks': w['calls'],
        'ticks': c['ticks'], 'missed_ticks': c['missed_ticks'],
        'held_predictions': c['held_predictions'], 'publish_failures': c['publish_failures'],
        'same_name_nodes': c['same_name_nodes'],
        'newton_subdivisions': st['subdivision_events'], 'newton_substeps': st['substeps'],
        'max_newton_solves_per_step': st['max_solves_per_step'],
        **{k: rc[k] for k in _SIMULATION_COUNTERS},
        'last_error': rt.last_error,
    }
    node_rejects = sum(c[f'rejected_{r}'] for r in NODE_REJECT_REASONS)
    rejected = rc['rejected_samples'] + node_rejects + c['rejected_parameter_sets'] + \
        c['rejected_clock_messages'] + rc['rejected_load_samples']
    in_vals = {k: rc[k] for k in _INPUT_COUNTERS}
    in_vals.update({f'rejected_{r}': c[f'rejected_{r}'] for r in NODE_REJECT_REASONS})
    in_vals.update({k: c[k] for k in _PARAMETER_COUNTERS})
    in_vals['command_timing'] = command_timing
    in_vals['stale_after_ms'] = rt.stale_after_ns * 1e-6
    in_vals['last_stamp_ns'] = rt.last_stamp_ns
    in_vals['resync_candidates'] = rt.resync_candidates
    in_vals['load_torque_nm'] = rt.load_torque
    in_vals['last_error'] = last_error
    in_level = diag.WARN if (rejected or rt.stale) else diag.OK
    in_msg = ', '.join(m for m in (
        f'{rejected} rejected input(s)' if rejected else '',
        'stream stale' if rt.stale else '') if m) or 'ok'
    comp = rt.compensator
    ff_level = diag.OK if comp is not None and not rc['compensation_errors'] else diag.ERROR
    ff_vals = {'available': comp is not None,
               'applied_to_prediction': rt.apply_compensation,
               'preview_time_s': rt.preview_ns * 1e-9,
               'pending_corrections': rt.pending,
               'corrections': rc['corrections'],
               'corrections_dropped': rc['corrections_dropped'],
               'last_correction_rad': rt.last_delta,
               'compensation_errors': rc['compensation_errors'],
               'error': rt.compensation_error}
    ff_msg = 'ok' if ff_level == diag.OK else (rt.compensation_error or 'compensation errors')
    return [
        diag.status(name, 'simulation', level, msg, sim_vals, HARDWARE_ID),
        diag.status(name, 'inputs', in_level, in_msg, in_vals, HARDWARE_ID),
        diag.status(name, 'feedforward', ff_level, ff_msg, ff_vals, HARDWARE_ID),
    ]


def model_check_status(name: str, check: ModelCheck, now_ns: int) -> diag.DiagnosticStatus:
    """The live model check (measured_joint_states vs the prediction) as status
    'model check'."""
    st = check.status_ns(now_ns)
    level = {'OK': diag.OK, 'WARN': diag.WARN, 'STALE': diag.STALE}[st.level]
    return diag.status(name, 'model check', level, st.message, st.values, HARDWARE_ID)


def backdrive_status(name: str, margin: float, margin_at_rest: float,
                     warn_below: float) -> diag.DiagnosticStatus:
    """Status 'back-drive': the margin now (at the predicted sliding speed) and at rest;
    WARN below ``node.backdrive_margin_warn``.  A margin below 1 is physics (the model
    shows the drive back-driven if the motor lets go), not a node error."""
    level = diag.WARN if margin < warn_below else diag.OK
    if margin < 1.0:
        msg = (f'back-drive margin {margin:.3g} < 1: the load would turn the worm back if the '
               'motor let go')
    elif level == diag.WARN:
        msg = f'back-drive margin {margin:.3g} below {warn_below:g}'
    else:
        msg = f'self-locking, margin {margin:.3g}'
    return diag.status(name, 'back-drive', level, msg,
                       {'margin': margin, 'margin_at_rest': margin_at_rest,
                        'warn_below': warn_below}, HARDWARE_ID)
