# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The demo servo's text: every line fits 80 columns (one status line on a terminal, one
line per completed move otherwise) and the summary at the end, with the same moves run
offline through the core beside the live figures (:func:`summary`)."""

from __future__ import annotations

import argparse
import math
from typing import Any, TextIO

import numpy as np

from ..studies.compensation_eval import SETTLE_TOLERANCE
from ..studies.demo_moves import MoveSummary, offline_moves

__all__ = ['LINE_WIDTH', 'MOVE_HEADER', 'fit', 'format_move', 'format_status', 'urad',
           'summary']

LINE_WIDTH = 80                 # every line the demo prints fits 80 columns


def urad(x: float, width: int = 7, sign: bool = False) -> str:
    """x [rad] in urad, right-aligned in ``width`` characters, as many decimals as fit."""
    if not math.isfinite(x):
        return f'{"-" if math.isnan(x) else ("+inf" if x > 0 else "-inf"):>{width}}'
    v = x * 1e6
    plus = '+' if sign else ''
    for d in (2, 1, 0):
        s = f'{v:{plus}{width}.{d}f}'
        if len(s) <= width:
            return s
    return f'{v:{plus}{width}.0e}'


def _ms(x: float) -> str:
    return 'never' if math.isinf(x) else ('-' if math.isnan(x) else f'{x * 1e3:.1f} ms')


def fit(line: str, width: int = LINE_WIDTH) -> str:
    return line if len(line) <= width else line[:width - 1] + '>'


MOVE_HEADER = ' move           t [s]  peak [urad]  ringing [urad]  rms [urad]  settling'


def format_move(m: MoveSummary) -> str:
    """One line per completed move (no terminal), in the columns of MOVE_HEADER."""
    rms = urad(m.tracking_rms, 10) if math.isfinite(m.tracking_rms) else f'{"":10}'
    return fit(f'{m.index:5d} {m.label:<4} {m.start:10.2f}  {urad(m.peak, 11)}  '
               f'{urad(m.ringing, 14)}  {rms}  {_ms(m.settling):>8}')


def format_status(t: float, e: float, scale: float, last: MoveSummary | None,
                  extra: str = '', width: int = LINE_WIDTH) -> str:
    """The one terminal line: time, live error with a bar, the last move's summary."""
    n = 6
    k = 0 if not (math.isfinite(e) and scale > 0) else int(round(min(1.0, abs(e) / scale) * n))
    bar = (' ' * (n - k) + '#' * k + '|' + ' ' * n) if e < 0 else \
        (' ' * n + '|' + '#' * k + ' ' * (n - k))
    s = f'{t:6.1f}s e{urad(e, 9, True)} urad [{bar}]'
    if last is not None:
        s += f' #{last.index} ring{urad(last.ringing, 7)}, {_ms(last.settling)}'
    if extra:
        s += ' ' + extra
    return fit(s, width - 1)          # never the last column: no wrap on any terminal


def _stats(values: list[float]) -> tuple[float, float]:
    a = np.asarray([v for v in values if math.isfinite(v)])
    return (float(np.median(a)), float(np.max(a))) if a.size else (math.nan, math.nan)


def summary(node: Any, opts: argparse.Namespace, compensated: bool | None,
             out: TextIO) -> None:
    def say(line: str) -> None:
        print(fit(line), file=out, flush=True)
    moves = node.tracker.moves
    say(f'demo done: {node.elapsed():.1f} s of {opts.pattern} moves, {node.interface} '
        f'references at {opts.rate:g} Hz' + (f', {(node.preview + node.lead) * 1e3:g} ms '
                                               'ahead' if node.interface == 'stamped' else ''))
    if node.interface == 'stamped':
        share = 100.0 * node.n_cc / node.sent if node.sent else 0.0
        say(f'  references {node.sent}, compensated commands {node.n_cc} ({share:.2f} %), '
            f'joint_states {node.n_js}')
        if node.latency_ns:
            ahead = np.asarray(node.latency_ns) * 1e-6
            say(f'  corrections arrived {np.percentile(ahead, 50):.2f} ms before their instant '
                f'(median), 1 % < {np.percentile(ahead, 1):.2f} ms')
    else:
        say(f'  commands {node.sent}, joint_states {node.n_js}, positioning errors '
            f'{node.n_err}')
    label = {True: 'with feed-forward', False: 'without feed-forward',
             None: 'feed-forward unknown'}[compensated]
    med, mx = _stats([m.ringing for m in moves])
    say(f'  {len(moves)} moves {label}: ringing median {med * 1e6:.2f}, '
        f'max {mx * 1e6:.2f} urad')
    settled = [m.settling for m in moves if math.isfinite(m.settling)]
    say(f'  largest error {node.peak_all * 1e6:.2f} urad; settled to '
        f'{SETTLE_TOLERANCE * 1e6:g} urad {len(settled)}/{len(moves)}'
        + (f', median {_ms(float(np.median(settled)))}' if settled else ''))
    if node.tracker.incomplete:   # a line of its own: never cut by the 80-column limit
        say(f'  {node.tracker.incomplete} moves with gaps (the stream was interrupted)')
    if opts.no_offline or not moves or node.interface != 'stamped':
        return
    # the same moves through the core, offline: with and without the feed-forward
    t_end = moves[-1].start + node.segments.period + 1e-3
    model = node.model
    if node.node_preview is not None and \
            node.node_preview != node.cfg.compensation.preview_time:
        # the feed-forward the node computes
        model = node.cfg.replace({'compensation.preview_time': node.node_preview})
    off = {c: {m.index: m for m in offline_moves(model, node.theta1, node.segments, t_end,
                                                 node.rate, c)} for c in (False, True)}
    same = [m for m in moves if m.index in off[False] and m.index in off[True]]
    if not same:
        return
    o_off = _stats([off[False][m.index].ringing for m in same])[0]
    o_on = _stats([off[True][m.index].ringing for m in same])[0]
    live = _stats([m.ringing for m in same])[0]
    say(f'  offline, same moves: ringing {o_off * 1e6:.2f} urad without, '
        f'{o_on * 1e6:.2f} with feed-forward')
    if compensated is not None:
        ref = off[compensated]
        dev = max(abs(m.ringing - ref[m.index].ringing) for m in same)
        say(f'  live vs offline ({label}): ringing differs by at most {dev:.1e} rad')
    if compensated and live > 0:
        say(f'  => ~/compensated_command applied: the antenna rings {o_off / live:.0f}x '
            'less than without')
