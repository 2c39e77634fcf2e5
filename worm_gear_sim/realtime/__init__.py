# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The node's real-time pipeline, in the core (no rclpy): :class:`RealtimePredictor`.

Reference samples in; feed-forward corrections (:class:`Correction`), predictions of the
simulated drive (:class:`Prediction`), events (:class:`Event`) and counters out; the offline
twin :func:`feedforward_series` drives the same object.  The rules of the stream (stamps,
preview, pauses, resyncs, the Float64 path, catch-up): docs/realtime.md.

The modules: :mod:`.predictor` (the public face), :mod:`.stamped_path` and
:mod:`.command_path` on :mod:`.sample_path`, :mod:`.stream_state`, :mod:`.admission`,
:mod:`.drive`, :mod:`.outputs`, :mod:`.offline`; import from here.  Beside the pipeline,
imported from their modules: :mod:`.command_timing`, :mod:`.replay`, :mod:`.model_check`.
"""

from .offline import feedforward_series
from .outputs import COUNTER_NAMES, Correction, Event, Output, Prediction, Prepared, Reject
from .predictor import CONFIRM_SAMPLES, RealtimePredictor
from .stream_state import STALE_MAX_INTERVAL, STALE_PERIODS

__all__ = ['RealtimePredictor', 'feedforward_series', 'Correction', 'Prediction', 'Event',
           'Output', 'Reject', 'Prepared', 'STALE_PERIODS', 'STALE_MAX_INTERVAL',
           'CONFIRM_SAMPLES', 'COUNTER_NAMES']
