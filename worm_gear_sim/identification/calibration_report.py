# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a calibration (:func:`~worm_gear_sim.identification.calibrate.calibrate`) shows and
writes, the same from every face of it (``worm-gear-sim calibrate`` and
``worm_gear_sim_calibrate``): its progress bar, the verdict, the printed report (with the
compensator the calibration recommends, when given) and the files FITTED.json (the
report), FITTED.png (the held-out and training moves before and after the fit, the verdict
in its title) and, only when accepted, FITTED.yaml."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

from ..config.files import write_params_yaml
from .report import jsonable

__all__ = ['StageBar', 'verdict_line', 'report_calibration']


class StageBar:
    """The progress of a calibration (:func:`~worm_gear_sim.identification.calibrate.
    calibrate`'s ``progress`` callback): one step per stage (each move's record, the fit,
    the validation, ..., the recommendation), the running stage's name as the bar's
    description; no bar when not ``enabled``."""

    def __init__(self, moves: int, enabled: bool) -> None:
        from .._support.progress import progress_bar
        self.bar = progress_bar(moves + 4, 'calibrate', 'stage') if enabled else None
        self.started = False

    def __call__(self, stage: str) -> None:
        if self.bar is None:
            return
        if self.started:
            self.bar.update(1)
        self.started = True
        if self.bar.n >= self.bar.total:      # a refit: one stage more than planned
            self.bar.total = self.bar.n + 1
        self.bar.set_description_str(stage)

    def close(self) -> None:
        if self.bar is not None:
            if self.started:
                self.bar.total = self.bar.n + 1
                self.bar.update(1)
            self.bar.close()


def verdict_line(res: Any) -> str:
    """``verdict: accepted`` or ``verdict: refused — <reasons>``."""
    return 'verdict: accepted' if res.accepted else \
        'verdict: refused — ' + '; '.join(res.reasons)


def report_calibration(res: Any, base: Any, keys: list[str], limits: Any, out: Path,
                       source: str, command: str, wall: float, plot: bool,
                       say_line: Any, advice: Any = None,
                       **extra: Any) -> tuple[Path, list[str]]:
    """Print the fit, the held-out errors and bounds, the verdict and (``advice``: a
    :func:`~worm_gear_sim.studies.recommendation.calibration_recommendation`) the
    recommended compensator and its predicted improvement; write FITTED.json (the report),
    the figure FITTED.png (the verdict on it) and, only when accepted, FITTED.yaml
    (``source``: where the records came from, for the YAML's header; ``extra``: more fields
    of the report).  Returns the report's path and the figures."""
    say_line(res.fit.table())
    direct = res.fit.frequency_info.get('direct', {})
    if direct.get('values'):
        say_line('direct estimates (constant-rate lags): ' + ', '.join(
            f'{k} = {v:.4g}' for k, v in direct['values'].items())
            + ('' if direct.get('play_seen', True) else ' (play not seen)'))
    say_line('the excitation shows: ' + (', '.join(res.seen) or 'none of the fitted keys'))
    for line in res.not_seen.values():
        say_line(f'NOT SEEN: {line}')
    for row_b, row_a in zip(res.validation_before, res.validation_after):
        for o in row_a:
            if o != 'name':
                say_line(f'held-out {row_a["name"]}: {o} RMS {100 * row_b[o]["rel"]:.2f} % '
                         f'-> {100 * row_a[o]["rel"]:.2f} % of its amplitude '
                         f'{row_a[o]["amplitude_rad"]:.3g} rad')
    for b, row in zip(res.bounds, res.validation_after):
        say_line(f'95 % bound on the theta4 RMS prediction error over a {b.duration:.3g} s '
                 f'move: {b.bound_rad:.3g} rad (misfit {b.misfit_rad:.3g}, parameters '
                 f'{b.spread_rad:.3g}); held-out {row["name"]}: '
                 f'{row["theta4"]["rms_rad"]:.3g} rad '
                 f'({"within" if b.covers(row["theta4"]["rms_rad"]) else "OUTSIDE"})')
    say_line(verdict_line(res))
    if advice is not None:
        for line in advice.lines():
            say_line(line)
    stem = out.with_suffix('')
    out.parent.mkdir(parents=True, exist_ok=True)
    report = res.fit.to_dict()
    report.update(command=command, **extra,
                  limits={k: getattr(limits, k) for k in ('max_angle', 'max_rate',
                                                          'max_accel', 'duration', 'start')},
                  moves=[{'name': m.name, 'role': m.role, 'profile': m.profile.describe(),
                          'duration_s': m.t_end} for m in res.moves],
                  validation={'before': res.validation_before, 'after': res.validation_after},
                  prediction_bound=[{'output': b.output, 'level': b.level,
                                     'duration_s': b.duration, 'bound_rad': b.bound_rad,
                                     'misfit_rad': b.misfit_rad, 'spread_rad': b.spread_rad}
                                    for b in res.bounds],
                  accepted=res.accepted, reasons=res.reasons, verdict=verdict_line(res),
                  recommendation=advice.to_dict() if advice is not None else None,
                  seconds=wall,
                  seen=res.seen, not_seen=res.not_seen,
                  output_yaml=None)
    figures = []
    if plot:
        from .plot import plot_fit
        worst = res.worst_held_out()
        figures.append(str(plot_fit(
            res.held_out + res.train, base, res.config, stem.with_suffix('.png'),
            'calibrate: held-out move and training moves',
            _figure_verdict(res) + (f' (held-out theta4 RMS {100 * worst:.2f} % of its '
                                    'amplitude)' if math.isfinite(worst) else ''))))
    report['figures'] = figures
    if res.accepted:
        header = [f'worm_gear_sim parameters calibrated ({source}); created '
                  f'{time.strftime("%Y-%m-%d %H:%M:%S")}',
                  f'held-out theta4 RMS {100 * res.worst_held_out():.2f} % of its amplitude']
        for k, v, (lo, hi) in zip(res.fit.keys, res.fit.values, res.fit.ci95):
            header.append(f'{k} = {v:.9g}  (95 % interval {lo:.6g} .. {hi:.6g})')
        write_params_yaml(res.config, out, header)
        report['output_yaml'] = str(out)
    json_path = stem.with_suffix('.json')
    json_path.write_text(json.dumps(jsonable(report), indent=2, allow_nan=True) + '\n')
    say_line(f'calibrated {len(keys)} parameter(s) in {wall:.1f} s; wrote {json_path}'
             + (f', {out}' if res.accepted else '') + (f', {", ".join(figures)}' if figures
                                                       else ''))
    return json_path, figures


def _figure_verdict(res: Any) -> str:
    """The verdict for the figure's title: the first reason only (a title is one line)."""
    if res.accepted:
        return 'verdict: accepted'
    more = f' (+{len(res.reasons) - 1} more)' if len(res.reasons) > 1 else ''
    return f'verdict: refused — {res.reasons[0] if res.reasons else "?"}{more}'
