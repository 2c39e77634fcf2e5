# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What an operator does to a running node, in-process and without rclpy: the core calls the
node makes (its real-time pipeline with the compensation applied, the live model check and
the live adaptation), a simulated drive that differs from the node's model (load, drag and
play: the core's :class:`EncoderPlant`, the twin's plant) answering each command, and the
operator's actions as methods of :class:`Operator`; :meth:`Operator.check` states what
must hold after each of them.  ``test/test_operations.py`` drives it by hypothesis
(``RuleBasedStateMachine``); ``benchmarks/bench_operations.py`` runs an operator's
sequence with the node and a plant node as processes.

The node's paths, as :mod:`worm_gear_sim.ros.node` and :mod:`worm_gear_sim.ros.adaptation`
call the core:

* a stamped reference: ``push`` (the caller's clock at reception), its predictions to the
  model check and, while adaptation is on, to the adaptation with its decision
  (``predicted``, ``step``); its corrections command the drive, whose encoder comes back
  to the model check and the adaptation (``measured``);
* a paused servo: the watch calls ``hold`` every 20 ms, and once the stream is stale the
  hold runs at the command rate; its held predictions go the same way; the drive holds its
  last command;
* a parameter set: :meth:`LiveAdaptation.reconfigure` (the node's ``pipeline`` and
  ``swapped``: the operator's set with what was learnt on top), or the same with a blended
  swap; ``adaptation.enabled`` false: nothing fed, true: fed again;
* ``~/reset_adaptation``: :meth:`LiveAdaptation.reset`;
* ``~/write_adapted_parameters``: the node's file text through the durable writer; a
  restart of the node from that file (``--params-file``) builds the pipeline, the check and
  the adaptation afresh from it (the drive goes on).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np

from worm_gear_sim._support.guarded_io import write_text_durably
from worm_gear_sim.adaptation.live import LiveAdaptation
from worm_gear_sim.adaptation.plant import EncoderPlant
from worm_gear_sim.config.files import load_config, params_document, params_yaml_text
from worm_gear_sim.config.usable import Config
from worm_gear_sim.realtime import Output, RealtimePredictor
from worm_gear_sim.realtime.model_check import ModelCheck
from worm_gear_sim.schema.validation import ConfigError
from worm_gear_sim.studies.adaptation_twin import BASE_NS, prepare_start, run_twin, scenario

LOAD, DRAG, PLAY = ('load.output_torque', 'load.output_viscous_coefficient', 'mesh.backlash')
#: The node's start set (adaptation on, the compensation applied: :func:`prepare_start`),
#: short windows so that an example of a few seconds learns and steps
START = {'adaptation.keys': [LOAD, DRAG, PLAY], 'adaptation.window': 0.3,
         'adaptation.step_interval': 0.1, 'adaptation.max_step': 0.05}
#: The drive: 2 N m of load, 20 N m s/rad of drag, 2 arcmin of play (none in the model)
PLANT = {LOAD: 2.0, DRAG: 20.0, PLAY: 5.8e-4}
SEED = 7
MS = 1_000_000
#: The node's stale margin (worm_gear_sim.ros.node.STALE_MARGIN) and watch period [ns]
STALE_MARGIN = 0.1
WATCH_NS = 20 * MS
#: The scan streamed (s); an operator's sequence never reaches its end
SCAN_SECONDS = 60.0
#: The twin's span compared bit for bit with a sequence of plain runs [s]
TWIN_SECONDS = 2.0
HEADER = '# worm_gear_sim: the model in use, written by ~/write_adapted_parameters\n'
#: Finite absurd and non-finite encoder values (and another drive's +3 rad, relative)
GLITCHES = (1e300, 1e150, -1e150, math.nan, math.inf)


def start_config() -> Config:
    return prepare_start(Config().replace(START))


def plant_config() -> Config:
    return Config().replace(PLANT)


_SHARED: dict[str, Any] = {}


def scan() -> tuple[np.ndarray, np.ndarray]:
    if 'scan' not in _SHARED:
        _SHARED['scan'] = scenario(start_config(), 'sector', SCAN_SECONDS)
    return _SHARED['scan']


def twin_record() -> list:
    """The offline twin's record of the same start, drive, scan and seed (per pushed
    sample: stamp, reference, [(stamp, encoder theta4, delta) of each correction])."""
    if 'twin' not in _SHARED:
        _SHARED['twin'] = run_twin(plant_config(), Config().replace(START), 'sector',
                                   TWIN_SECONDS, seed=SEED, record=True).record
    return _SHARED['twin']


class Operator:
    """The node in operation (module docstring); ``workdir``: where it writes."""

    def __init__(self, workdir: Path) -> None:
        self.workdir = Path(workdir)
        self.params_file = self.workdir / 'adapted.yaml'
        cfg = start_config().replace({'adaptation.params_file': str(self.params_file)})
        self.t, self.x = scan()
        self._build(cfg, base_ns=BASE_NS)
        self.plant = EncoderPlant(plant_config(), float(self.x[0]), noise=1e-6,
                                  encoder_bits=20, seed=SEED)
        self.plant_ns = BASE_NS
        self.last_command: tuple[int, float] | None = None
        self.last_measured = math.nan
        self.k = 0                    # the next sample of the scan
        self.offset = 0               # the stamps' shift by the pauses so far [ns]
        self.now = BASE_NS            # the node's clock [ns]
        self.pure = True              # nothing but plain samples so far: the twin's run
        self.record: list = []        # while pure: as the twin's record
        self.written: dict[str, Any] | None = None     # the flat set last written
        self.nominal_fallbacks = 0    # seen by check(): must stay 0
        self.outputs = 0

    def _build(self, cfg: Config, base_ns: int | None) -> None:
        """The node's parts for ``cfg`` (at the start, and at a restart of the node)."""
        self.pred = RealtimePredictor(cfg, apply_compensation=True, base_ns=base_ns,
                                      stale_margin=STALE_MARGIN)
        self.live = LiveAdaptation(self.pred, cfg.node.joint_names[1:])
        self.check_ = ModelCheck.of(cfg.node)
        self.enabled = cfg.adaptation.enabled
        self.antenna = cfg.node.joint_names[3]
        self.sent: list[int] = []         # the stamps of the references accepted
        self.answered: set[int] = set()   # and of the corrections published
        self._baseline()

    def copy(self) -> Operator:
        return copy.deepcopy(self)

    # ---- the node's paths --------------------------------------------------------------
    def stamp(self, k: int) -> int:
        return BASE_NS + int(round(self.t[k] * 1e9)) + self.offset

    def _handle(self, out: Output) -> None:
        """What the node does with one call's output: check it is finite, predictions to
        the model check and the adaptation (then its decision), corrections to the drive,
        its encoder back."""
        self.outputs += 1
        for c in out.corrections:
            assert math.isfinite(c.delta) and math.isfinite(c.compensated), c
            self.answered.add(c.stamp_ns)
        for p in out.predictions:
            assert all(math.isfinite(v) for v in (*p.position, *p.velocity, *p.effort,
                                                  p.positioning_error, p.worm_error)), p
            self.check_.predicted_ns(p.stamp_ns, p.theta)
        live = self.live if self.enabled else None
        if live is not None and out.predictions:
            for p in out.predictions:
                live.predicted(p.stamp_ns, p.theta)
            live.step(out.predictions[-1].stamp_ns)
        got = []
        for c in out.corrections:
            if self.last_command is not None and c.stamp_ns <= self.last_command[0]:
                continue                    # the drive takes each instant once
            meas = self._command(c.stamp_ns, c.compensated)
            got.append((c.stamp_ns, meas, c.delta))
            self.encoder(c.stamp_ns, [self.antenna], [meas])
        if self.pure:
            self.record.append(got)

    def _command(self, ns: int, value: float) -> float:
        self.last_command = (ns, value)
        self.last_measured = self.plant.command((ns - self.plant_ns) * 1e-9, value)[1]
        return self.last_measured

    def encoder(self, stamp_ns: int, names: list, positions: list) -> str | None:
        """A measured_joint_states message: the model check, then the adaptation; the
        adaptation's rejection reason (None: used or waiting, or adaptation off)."""
        got = self.check_.offer_ns(stamp_ns, names, positions)
        if not isinstance(got, str):
            assert np.all(np.isfinite(got[1])), got
        if not self.enabled:
            return None
        return self.live.measured(stamp_ns, names, positions)

    # ---- the operator's actions ----------------------------------------------------------
    def samples(self, n: int) -> None:
        """``n`` stamped references of the scan, each received at its stamp."""
        for _ in range(n):
            ns = self.stamp(self.k)
            self.now = max(self.now, ns)
            self._push(ns)

    def _push(self, ns: int) -> None:
        out = self.pred.push(ns, float(self.x[self.k]), now_ns=self.now)
        assert out.accepted, (self.k, out.rejected)
        self.sent.append(ns)
        self.k += 1
        self._handle(out)

    def _wait(self, until_ns: int) -> None:
        """No reference arrives until ``until_ns``: the node's watch (every 20 ms), then,
        once the stream is stale, its hold at the command rate."""
        while self.now < until_ns:
            stale = self.pred.stale
            self.now = min(until_ns, self.now + (MS if stale else WATCH_NS))
            self._handle(self.pred.hold(self.now))

    def pause(self, seconds: float) -> None:
        """The servo stops for ``seconds`` and resumes the scan where it stopped; the drive
        holds its last command meanwhile."""
        self.pure = False
        last = self.stamp(self.k - 1) if self.k else self.now
        shift = int(round(seconds * 1e9))
        self._wait(last + shift)
        self.offset += shift
        if self.last_command is not None:       # held up to the next command's period
            ns, value = self.last_command
            hold_to = self.stamp(self.k) - MS
            if hold_to > ns:
                self.plant.command((hold_to - self.plant_ns) * 1e-9, value)

    def late(self, seconds: float, n: int) -> None:
        """The references stall in transport for ``seconds`` (the stream is held as stale),
        then the ``n`` held back arrive at once, stamped as they were sent."""
        self.pure = False
        last = self.stamp(self.k - 1) if self.k else self.now
        self._wait(last + int(round(seconds * 1e9)))
        for _ in range(n):
            ns = self.stamp(self.k)
            self.now = max(self.now, ns)
            self._push(ns)

    def parameter_set(self, overrides: dict[str, Any], blend: float = 0.0) -> bool:
        """The operator's parameter set (the node's pipeline and swapped, at once);
        ``blend`` > 0: the swap blended over that long.  False: refused, nothing changed."""
        self.pure = False
        live, pred = self.live, self.pred
        before = (pred.config, live.adapter, dict(live.counters))
        try:
            if blend <= 0.0:
                live.reconfigure(overrides)
            else:
                declared = live.declared.replace(overrides)
                carried = live.carried_values(declared, overrides.keys())
                prepared = pred.prepare(declared.replace(carried) if carried else declared)
                pred.reconfigure(prepared, blend=blend)
                live.carry_over(declared, overrides.keys())
        except ConfigError:
            assert (pred.config, live.adapter, live.counters) == before, \
                'a refused set changed the node'
            return False
        if 'adaptation.enabled' in overrides:
            self.enabled = bool(overrides['adaptation.enabled'])
        return True

    def reset(self) -> None:
        self.pure = False
        self.live.reset()

    def glitch(self, kind: str, value: float = 0.0, count: int = 1) -> list[str | None]:
        """Bad encoder messages stamped after the last one: ``value`` (a finite absurd or
        non-finite one), ``duplicate`` (the antenna named twice), ``other`` (another
        drive's encoder, +3 rad), ``flood`` (``count`` plausible ones within one command
        period).  Returns the adaptation's verdicts."""
        self.pure = False
        if self.last_command is None:
            return []
        ns, near = self.last_command[0], self.last_measured
        names, reasons = [self.antenna], []
        for j in range(count):
            stamp = ns + 1 + j * (MS // max(count, 1))
            if kind == 'value':
                msg = (names, [value])
            elif kind == 'duplicate':
                msg = (names * 2, [near, near])
            elif kind == 'other':
                msg = (names, [near + 3.0])
            else:
                msg = (names, [near + 1e-6 * (j % 3)])
            reasons.append(self.encoder(stamp, *msg))
        return reasons

    def write(self) -> dict[str, Any]:
        """``~/write_adapted_parameters``: the model in use through the durable writer."""
        self.pure = False
        cfg = self.live.params_config()
        write_text_durably(cfg.adaptation.params_file,
                           HEADER + params_yaml_text(params_document(cfg)))
        self.written = cfg.to_flat_dict()
        return self.written

    def restart(self) -> None:
        """The node stops during a pause and starts from the file it wrote (written now if
        it has not yet); the drive goes on."""
        if self.written is None:
            self.write()
        self.pause(0.2)
        cfg = load_config(self.params_file)
        assert cfg.to_flat_dict() == self.written, 'the written file reloads another set'
        self._build(cfg, base_ns=None)

    # ---- what must hold ------------------------------------------------------------------
    def _baseline(self) -> None:
        self._counts = self._counters()

    def _counters(self) -> dict[str, int]:
        live = self.live
        return {**{f'live.{k}': v for k, v in live.counters.items()},
                **{f'pred.{k}': v for k, v in self.pred.counters.items()},
                **{f'check.{k}': v for k, v in self.check_.rejections.items()}}

    def in_use(self) -> dict[str, Any]:
        """The estimated keys' values in the pipeline's set, and in the declared set."""
        flat, declared = self.pred.config.to_flat_dict(), self.live.declared.to_flat_dict()
        return {k: (flat[k], declared[k]) for k in self.live.adapter.layout.keys}

    def check(self, before: dict[str, Any] | None = None, forgets: frozenset = frozenset()
              ) -> None:
        """The invariants after an action (``before``: :meth:`in_use` before it; the keys
        it may return to the declared set: ``forgets``)."""
        live, pred = self.live, self.pred
        # counters never decrease
        counts = self._counters()
        for k, v in self._counts.items():
            assert counts.get(k, 0) >= v, (k, v, counts.get(k))
        self._counts = counts
        # the pipeline runs the declared set with the adapted values on top
        flat, declared = pred.config.to_flat_dict(), live.declared.to_flat_dict()
        keys = set(live.adapter.layout.keys)
        applied = live.adapter.applied_values()
        for k, v in flat.items():
            assert _same(v, applied[k] if k in keys else declared[k]), \
                (k, v, applied.get(k), declared[k])
        # what the node shows is finite
        for k, v in {**live.estimates(), **applied}.items():
            assert np.all(np.isfinite(v)), (k, v)
        rms = live.adapter.window_rms()
        if live.adapter._sc.item(0) > 0.0:
            assert all(math.isfinite(v) for v in rms.values()), rms
        assert np.all(np.isfinite(live.adapter.theta)) and np.all(np.isfinite(live.adapter.P))
        mon = self.check_.monitor.rms()
        assert not np.any(np.isinf(mon)), mon
        # the model in use never falls back to the declared set without a reset
        if before is not None:
            now = self.in_use()
            for k, (used, nominal) in before.items():
                if k in forgets or k not in now:
                    continue
                if not _same(used, nominal) and _same(*now[k]):
                    self.nominal_fallbacks += 1
                    raise AssertionError(f'{k} fell back to the declared {now[k][1]} '
                                         f'(was {used})')
        # every reference accepted is answered (but those waiting for the preview)
        waiting = pred.pending
        missing = [ns for ns in self.sent[:len(self.sent) - waiting] if ns not in self.answered]
        assert not missing, f'{len(missing)} references not answered, the first {missing[0]}'
        # the twin, while nothing but samples streamed
        if self.pure:
            twin = twin_record()
            n = min(len(self.record), len(twin))
            assert self.record[:n] == [got for _, _, got in twin[:n]], 'not the twin'


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) or isinstance(b, (list, tuple)):
        a, b = list(a), list(b)
        n = max(len(a), len(b))
        return a + [0.0] * (n - len(a)) == b + [0.0] * (n - len(b))
    return bool(a == b)
