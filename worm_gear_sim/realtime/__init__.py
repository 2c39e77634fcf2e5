# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The real-time pipeline of the node, in the core (no rclpy): :class:`RealtimePredictor`.

One object turns a stream of reference samples theta1_ref into

* **corrections** (:class:`Correction`): the feed-forward delta of
  :class:`~worm_gear_sim.compensation.Compensator` for every accepted sample, stamped with
  the sample's stamp, and ``compensated = theta1_ref + delta`` (what the servo should
  command for that instant);
* **predictions** (:class:`Prediction`): the simulated drive
  (:class:`~worm_gear_sim.dynamics.simulation.Simulator`) at the instant they predict:
  theta1..theta4, rates, shaft torques, the antenna positioning error and the worm error;
* **events** (:class:`Event`) the node logs once (warning): resyncs, clock restarts, a
  stale or resumed stream, overruns, simulation or compensation errors;
* **counters** (:attr:`RealtimePredictor.counters`): integers with stable names for
  /diagnostics.

The node (``worm_gear_sim.ros``) only translates messages into these calls and back.
``feedforward_series`` (the offline twin, :mod:`.offline`) drives the same object.

Time
    Stamps are integer nanoseconds on the caller's clock (ROS time: epoch ~1.7e18 ns, or
    /clock with ``use_sim_time``).  Internally every time is ``(stamp - base) * 1e-9``
    seconds, with ``base`` the first accepted stamp (or ``base_ns``): a float of epoch
    seconds would lose ~0.2 us of resolution, i.e. ~7e-6 rad of correction.

Stamped path (``push``; ``sensor_msgs/JointState`` ``worm_angle_reference``)
    ``push(stamp_ns, theta1_ref, now_ns=...)`` validates the sample and rejects it with a
    :class:`Reject` reason (counted as ``rejected_<reason>``; the state is untouched):
    NaN, inf, ``|theta1_ref| > node.max_command_abs``, a stamp <= 0, a stamp more than
    ``max_stamp_age`` before or ``max_stamp_lead`` after ``now_ns``, a stamp equal to
    (``duplicate``) or older than (``out_of_order``) the last accepted sample, a change of
    more than ``node.max_command_jump`` from the last accepted sample (``jump``).
    Accepted samples are processed in stamp order:

    * With ``compensation.preview_time`` P the servo streams its reference P ahead: the
      correction for stamp t is computed (the compensator evaluated at exactly t) as soon
      as a sample stamped at or after t + P has been accepted, and returned by that push.
      With P = 0 every push returns its own correction.
    * The simulator is advanced to each sample's stamp with the applied command (samples
      joined as ``node.command_interpolation`` says): theta1_ref at once when the
      compensation is not applied; theta1_ref + delta when its correction is ready when it
      is (``apply_compensation``, default ``node.compensation_applied``).  Each advance
      returns a prediction stamped with the sample's stamp.
    * The result depends only on the accepted (stamp, value) pairs, never on when or in
      which bursts they arrive: ``feedforward_series`` of the same pairs gives the same
      deltas (tested to <= 1e-6 rad; measured bit for bit).

Gaps, pauses and the stale stream
    Let G = max(3.5 / node.publish_rate_hz, 2 min(last sample interval, 50 ms)).  A stamp
    more than G after the previous sample means the stream paused and the reference RESTED
    at its last value: rest samples (the last value, stamps previous + G + k/publish_rate,
    k = 0..K-1, K covering the filter and the preview) are inserted before it.  They are
    fed to the compensator and the simulator but produce no :class:`Correction` (the servo
    never sent them).  ``hold(now_ns)``, called by the node's slow timer, declares the
    stream stale when samples stopped ARRIVING: the stream's time is ``now_ns``, less the
    lag of the last accepted sample's stamp behind its arrival when its stamp lagged
    (transport and scheduling delay are normal: a steady stream whose stamps are 0.5 s old
    is not a paused one); the stream is stale when its time is more than G +
    ``stale_margin`` after the last sample.  Then ``hold`` inserts the rest samples due by
    the stream's time (the same ones a later sample would insert, so the deltas stay those
    of the offline twin), releases the corrections that were waiting for a preview,
    advances the simulator holding the last command up to the stream's time and returns
    that held prediction stamped with it; ``stale`` is True (event ``stream_stale``
    once).  Samples older than the accepted window (``max_stamp_age``) are rejected as
    ``too_old``.  The next accepted sample ends it (``stream_resumed``).
    A sample that arrives while the stream is held as stale with a stamp after the last
    sample but before an inserted rest sample was late, not paused (a reliable transport
    repairing a loss delivers the samples held back in a burst): the stale hold is
    retracted, the state before it restored (one copy per stale event), and the late
    samples are taken as if in time (``stale_retractions``, event ``stale_retracted``).
    The held predictions stay published; corrections the hold released (with a preview)
    are released again with the late samples.  Load samples accepted meanwhile make the
    hold final (a retraction would lose them).

Resync policy (jumps and restarts)
    A rejected ``jump`` sample, or an ``out_of_order`` one more than 100 ms older than the
    last sample (a late packet is not a restart), is kept as a candidate.  When
    ``confirm_samples`` (3) candidates in a row agree with each other (stamps increasing
    by at most 50 ms, values within ``node.max_command_jump``), the new level or timeline
    is real (a servo that really moved 3 rad; a servo whose stamps restarted): the pipeline
    resynchronises: corrections waiting for a preview are released (the old reference
    rested), the simulator restarts at rest at the first candidate (static equilibrium)
    and the other candidates follow; counted in ``resyncs``, event ``resync``.  A single
    outlier (a spike, a late packet) stays rejected.  A candidate is counted once, when
    its fate is known: accepted with the confirmed resync, or rejected under its reason
    when the chain breaks (until then it is one of ``resync_candidates``).
    A caller clock going backwards
    (``now_ns`` earlier than the previous ``now_ns`` by more than 1 ms: a simulator reset,
    a looping bag with ``use_sim_time``) re-initialises at once: pending corrections of
    the old timeline are dropped (``corrections_dropped``), the next accepted sample
    starts afresh (new base; ``clock_restarts``, event ``clock_restart``).

Float64 path (``push_command`` + ``tick``; ``std_msgs/Float64`` ``worm_angle_command``)
    Unstamped commands are handed over with their reception time; ``tick(now_ns)`` at
    ``node.publish_rate_hz`` turns them into samples as ``node.command_timing`` says
    (``tick``: the newest command since the previous tick is a sample at the tick;
    ``reception``; ``stream``: :class:`~worm_gear_sim.realtime.command_timing.StreamClock`; with
    ``sim_time`` the /clock reading at reception), feeds them through the same sample
    path (a sample not after the previous one replaces its value: ``merged_samples``),
    holds the last command up to the tick (or to the last corrected sample when a preview
    delays the applied compensation) and returns one prediction at that instant.  The
    first tick after the first command starts the simulation at rest at the newest command.
    A merged sample re-emits its own correction; with a preview, corrections released
    earlier whose window reached that sample keep the value they were computed with.
    The stream is stale after G without a command (no margin: tick stamps are never late).
    The pipeline serves one input at a time: a valid stamped sample after Float64 commands,
    or a tick with queued commands after stamped samples, restarts it on the other input
    (event ``input_changed``, counted in ``input_switches``); a tick without queued
    commands leaves a stamped stream alone.  Each input has its own clock (``push`` and
    ``hold``: the stamps' clock, ROS time in the node; ``tick``: the node's monotonic clock
    or /clock): a switch is never a clock going back.

Catch-up
    The simulator never integrates more than ``node.max_catch_up`` seconds for one sample
    or hold; the rest of the interval is skipped (``Simulator.resync``, counted in
    ``overruns`` and ``dropped_time_ns``, event ``overrun``).  ``node.max_catch_up`` must
    be at least the tick period 1 / ``node.publish_rate_hz`` (a :class:`ConfigError`
    otherwise), so the physics always advances.

Parameters are swapped with :meth:`RealtimePredictor.reconfigure`; the expensive part
(compensator design, the model's matrices) is :meth:`RealtimePredictor.prepare`, which the
node can run off the real-time path.

The package: :mod:`.predictor` (the public face: configuration, clocks, restarts), the two
input paths :mod:`.stamped_path` (``push``, ``hold`` and its retraction, the resync) and
:mod:`.command_path` (``push_command``, ``tick``) on the shared :mod:`.sample_path` (the
samples through the compensator and the simulated drive, rest samples, the stale stream,
load samples), :mod:`.stream_state` (the stream's declared state, :class:`StreamState`, and
what a stale hold saves of it with copies of the compensator and the drive: a retraction
takes back the stream and nothing else, neither the callers' clocks nor resync candidates
nor queued commands), :mod:`.admission` (the input checks and the confirmation of a jump,
once for every input), :mod:`.drive` (the simulator side: advance, catch-up, predictions),
:mod:`.blend` (a swapped-in compensator handed over; the new one alone once it has ended),
:mod:`.outputs` (what a call returns, the counter names), :mod:`.offline`
(``feedforward_series``, the offline twin); import from here.
Beside the pipeline: :mod:`.command_timing` (sample times of an unstamped command stream),
:mod:`.replay` (a recorded bag through the same pipeline) and :mod:`.model_check` (the live
residual check of the model), imported from their modules.
"""

from .offline import feedforward_series
from .outputs import COUNTER_NAMES, Correction, Event, Output, Prediction, Prepared, Reject
from .predictor import CONFIRM_SAMPLES, RealtimePredictor
from .stream_state import STALE_MAX_INTERVAL, STALE_PERIODS

__all__ = ['RealtimePredictor', 'feedforward_series', 'Correction', 'Prediction', 'Event',
           'Output', 'Reject', 'Prepared', 'STALE_PERIODS', 'STALE_MAX_INTERVAL',
           'CONFIRM_SAMPLES', 'COUNTER_NAMES']
