# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The demo servo's text: every line fits 80 columns.  One status line on a terminal, a table
of one row per move otherwise, with a group of columns per node under test (without and with
the feed-forward, side by side) under a legend that says what each column means, and the
summary at the end, with the same moves run offline through the core beside the live figures
(:func:`summary`)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any, TextIO

import numpy as np

from ..studies.compensation_eval import SETTLE_TOLERANCE
from ..studies.demo_moves import MoveSummary, offline_moves

__all__ = ['LINE_WIDTH', 'fit', 'urad', 'settle_text', 'group_label', 'node_lines', 'legend',
           'table_header', 'format_row', 'format_status', 'summary']

LINE_WIDTH = 80                 # every line the demo prints fits 80 columns
_LEFT = 18                      # the move's index, label and start time
_GROUP = 29                     # the columns of one node: peak, ring, rms, settle


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


def _seconds(x: float) -> str:
    """A duration in at most 7 characters: '4.0 ms', '0.43 s'."""
    return f'{x * 1e3:.1f} ms' if x < 0.0995 else f'{x:.2f} s'


def settle_text(m: MoveSummary | None) -> str:
    """The settle column: the settling time, or '>0.43 s' when the move did not settle
    within its span (the bound it exceeds), '-' when unknown."""
    if m is None or math.isnan(m.settling_bound):
        return '-'
    return _seconds(m.settling) if math.isfinite(m.settling) else \
        '>' + _seconds(max(0.0, m.settling_bound))


def fit(line: str, width: int = LINE_WIDTH) -> str:
    return line if len(line) <= width else line[:width - 1] + '>'


def group_label(compensated: bool | None, name: str) -> str:
    """A node's columns are titled by what it predicts."""
    return {True: 'with feed-forward', False: 'without feed-forward'}.get(
        compensated, name.lstrip('/'))


def node_lines(name: str, compensated: bool | None) -> list[str]:
    """What a node under test predicts, for the lines before the table."""
    what = {True: 'the drive commanded theta1_ref + delta (~/compensated_command)',
            False: 'the drive commanded theta1_ref',
            None: 'node.compensation_applied unknown (no parameter answer)'}[compensated]
    return [fit(f'  {group_label(compensated, name)}: node {name.lstrip("/")},'),
            fit(f'    {what}')]


def legend() -> list[str]:
    """What each column of the table means."""
    tol = f'{SETTLE_TOLERANCE * 1e6:g}'
    return ['per node, e in urad: peak = largest |e| in the move; ring = largest',
            '  |e - rest| once the applied command rests; rms = e while the reference',
            '  moves at a constant rate; settle = from the end of the motion until |e|',
            f'  stays within {tol} urad (>T: still outside T after it, when the next',
            '  move starts)']


def table_header(labels: Sequence[str]) -> list[str]:
    """Two lines: each node's title over its columns, then the column names."""
    titles = ' ' * _LEFT + ''.join(' ' + f' {lab} '.center(_GROUP - 1, '-') for lab in labels)
    names = f'{"move":>5} {"":<4} {"t [s]":>7}' + \
        f' {"peak":>6} {"ring":>6} {"rms":>6} {"settle":>7}' * len(labels)
    return [fit(titles), fit(names)]


def format_row(moves: Sequence[MoveSummary | None]) -> str:
    """One row: the move (the first summary present) and each node's columns ('-' where
    a node lost the move)."""
    first = next(m for m in moves if m is not None)
    row = f'{first.index:5d} {first.label:<4} {first.start:7.2f}'
    for m in moves:
        if m is None:
            row += f' {"-":>6} {"-":>6} {"-":>6} {"-":>7}'
        else:
            row += (f' {urad(m.peak, 6)} {urad(m.ringing, 6)} {urad(m.tracking_rms, 6)} '
                    f'{settle_text(m):>7}')
    return fit(row)


def format_status(t: float, errors: Sequence[tuple[str, float]],
                  last: Sequence[MoveSummary | None], width: int = LINE_WIDTH) -> str:
    """The one terminal line: time, each node's live error, the last move's ringing."""
    s = f'{t:6.1f}s' + ''.join(f' {label} {urad(e, 8, True)}' for label, e in errors) + ' urad'
    done = [m for m in last if m is not None]
    if done:
        s += f'  #{done[0].index} ring ' + '/'.join(f'{m.ringing * 1e6:.1f}' for m in done)
    return fit(s, width - 1)          # never the last column: no wrap on any terminal


def _stats(values: list[float]) -> tuple[float, float]:
    a = np.asarray([v for v in values if math.isfinite(v)])
    return (float(np.median(a)), float(np.max(a))) if a.size else (math.nan, math.nan)


def summary(node: Any, opts: argparse.Namespace, out: TextIO) -> None:
    """The end: what was streamed and answered, each node's moves, the same moves offline
    through the core, and the benefit of the feed-forward in one line."""
    def say(line: str) -> None:
        print(fit(line), file=out, flush=True)
    say(f'demo done: {node.elapsed():.1f} s of {opts.pattern} moves, {node.interface} '
        f'references at {opts.rate:g} Hz' + (f', {(node.preview + node.lead) * 1e3:g} ms '
                                               'ahead' if node.interface == 'stamped' else ''))
    answers = ', '.join(f'{w.label.split()[0]} {w.n_err}' for w in node.shown)
    if node.interface == 'stamped':
        share = 100.0 * node.n_cc / node.sent if node.sent else 0.0
        say(f'  references {node.sent}, compensated commands {node.n_cc} ({share:.2f} %)')
        say(f'  positioning errors: {answers}')
        if node.latency_ns:
            ahead = np.asarray(node.latency_ns) * 1e-6
            say(f'  corrections arrived {np.percentile(ahead, 50):.2f} ms before their instant '
                f'(median), 1 % < {np.percentile(ahead, 1):.2f} ms')
    else:
        say(f'  commands {node.sent}; positioning errors: {answers}')
    live: dict[bool | None, float] = {}
    for w in node.shown:
        moves = w.tracker.moves
        label = {True: 'with feed-forward', False: 'without feed-forward'}.get(
            w.compensated, f'of {w.name.lstrip("/")}')
        med, mx = _stats([m.ringing for m in moves])
        live[w.compensated] = med
        say(f'  {len(moves)} moves {label}: ringing median {med * 1e6:.2f}, '
            f'max {mx * 1e6:.2f} urad')
        settled = [m.settling for m in moves if math.isfinite(m.settling)]
        rms = _stats([m.tracking_rms for m in moves])[0]
        say(f'    rms median {rms * 1e6:.2f} urad, largest error {w.peak_all * 1e6:.2f} urad')
        say(f'    settled to {SETTLE_TOLERANCE * 1e6:g} urad {len(settled)}/{len(moves)}'
            + (f', median {_seconds(float(np.median(settled)))}' if settled else ''))
        if w.tracker.incomplete:   # a line of its own: never cut by the 80-column limit
            say(f'    {w.tracker.incomplete} moves with gaps (the stream was interrupted)')
    offline = _offline(node, opts, say)
    base = live.get(False, offline.get(False, math.nan))
    with_ff = live.get(True, math.nan)
    if with_ff > 0 and math.isfinite(base):
        say(f'=> ~/compensated_command applied: the antenna rings {base / with_ff:.0f}x less '
            'than without')
        say(f'   (median ringing {with_ff * 1e6:.2f} against {base * 1e6:.2f} urad, '
            + ('both live)' if False in live else 'without: offline)'))


def _offline(node: Any, opts: argparse.Namespace, say: Any) -> dict[bool, float]:
    """The same moves through the core without and with the feed-forward: their median
    ringing, and how far each node's live ringing is from its offline twin."""
    moves = [m for w in node.watched for m in w.tracker.moves]
    if opts.no_offline or not moves or node.interface != 'stamped':
        return {}
    t_end = max(m.start for m in moves) + node.segments.period + 1e-3
    model = node.model
    if node.node_preview is not None and \
            node.node_preview != node.cfg.compensation.preview_time:
        # the feed-forward the node computes
        model = node.cfg.replace({'compensation.preview_time': node.node_preview})
    off = {c: {m.index: m for m in offline_moves(model, node.theta1, node.segments, t_end,
                                                 node.rate, c)} for c in (False, True)}
    indices = {m.index for m in moves} & set(off[False]) & set(off[True])
    if not indices:
        return {}
    medians = {c: _stats([off[c][k].ringing for k in indices])[0] for c in (False, True)}
    say(f'  offline, same moves: ringing {medians[False] * 1e6:.2f} urad without, '
        f'{medians[True] * 1e6:.2f} with feed-forward')
    for w in node.shown:
        if w.compensated is None:
            continue
        same = [m for m in w.tracker.moves if m.index in indices]
        if same:
            dev = max(abs(m.ringing - off[w.compensated][m.index].ringing) for m in same)
            label = 'with' if w.compensated else 'without'
            say(f'  live vs offline ({label} feed-forward): ringing differs by at most '
                f'{dev:.1e} rad')
    return medians
