# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The global stage before the local fit: direct estimates of the play, the load torque and
the antenna drag from the constant-rate segments of the records, then a scan of the play.

On a constant-rate segment the antenna's lag is steady, e = -s b / 2 - (T + c u omega) C;
:func:`direct_estimates` solves it over the segments (:func:`steady_segments`) for the
consistent flank pattern, :func:`compliance` gives C, and :func:`scan_play` picks the
best play on the time-domain cost.  docs/identification.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from ..schema.validation import ConfigError
from .data import predict

__all__ = ['PLAY', 'LOAD', 'DRAG', 'DIRECT_KEYS', 'Segment', 'steady_segments', 'compliance',
           'DirectEstimate', 'direct_estimates', 'best_on_family', 'best_of',
           'simulated_rms', 'MISFIT_OK', 'scan_play', 'SCAN_FACTORS']

PLAY = 'mesh.backlash'
LOAD = 'load.output_torque'
DRAG = 'load.output_viscous_coefficient'
DIRECT_KEYS = (PLAY, LOAD, DRAG)
#: Shortest constant-rate run used [s] and the share of it skipped at its start (the
#: transient after the ramp, the flank change after a reversal).
MIN_RUN = 0.03
SKIP_SHARE = 0.4
#: Relative tolerance of "constant" rate.
RATE_TOL = 1e-3
#: Absolute tolerance [N m] of the flank pattern's consistency (a gear with neither load
#: nor drag floats in the play: its flank is undetermined).
TORQUE_TOL = 0.02
#: Factors on the play's direct estimate tried by :func:`scan_play`.
SCAN_FACTORS = (0.8, 0.88, 0.94, 1.0, 1.06, 1.13, 1.25)
#: Shares of the lag jump between the flanks tried as the play when one rate each way
#: cannot separate the play from the drag (:attr:`DirectEstimate.family`).
#: Static misfit [rad] below which the flank equations hold on every segment (noise, encoder
#: steps and the linear model's error are ~1 urad); above it a segment may float in the play.
MISFIT_OK = 5e-6
FAMILY_SHARES = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.97)


@dataclass(frozen=True)
class Segment:
    """A steady constant-rate segment of a record: its times, the worm rate [rad/s] and the
    mean measured lag e = theta4 - u theta1 [rad]."""

    record: str
    t0: float
    t1: float
    rate: float
    lag: float
    samples: int


def steady_segments(records: Sequence[Record], u: float) -> list[Segment]:
    """The steady parts of the constant-rate runs of the commands (theta4 measured)."""
    out = []
    for r in records:
        if 'theta4' not in r.measured:
            continue
        t = np.asarray(r.t, float)
        th1 = np.asarray(r.theta1, float)
        if t.size < 8:
            continue
        v = np.diff(th1) / np.diff(t)
        n = v.size
        i = 0
        while i < n:
            if abs(v[i]) <= 0.0:
                i += 1
                continue
            j = i
            while j + 1 < n and abs(v[j + 1] - v[i]) <= RATE_TOL * abs(v[i]):
                j += 1
            # samples i .. j + 1 lie on the run
            t0, t1 = t[i], t[j + 1]
            if t1 - t0 >= MIN_RUN:
                ts = t0 + SKIP_SHARE * (t1 - t0)
                sel = (t >= ts) & (t <= t1)
                e = r.measured['theta4'][sel] - u * th1[sel]
                out.append(Segment(r.name, float(ts), float(t1), float(np.mean(v[i:j + 1])),
                                   float(np.mean(e)), int(sel.sum())))
            i = j + 1
    return out


def compliance(base: Config) -> float:
    """C [rad/(N m)]: the static lag theta4 - u theta1 per N m of load torque on the antenna
    (play 0), from the model's static equilibria at +-1 N m."""
    lags = []
    t = np.arange(20) * 1e-3
    for tl in (1.0, -1.0):
        cfg = base.replace({PLAY: 0.0, LOAD: tl})
        m = DriveModel(cfg)
        rec = Record(name='rest', t=t, theta1=np.zeros_like(t), measured={'theta4': t})
        p = predict(m, rec)
        lags.append(float(p['theta4'][0]))
    return -(lags[0] - lags[1]) / 2.0


@dataclass
class DirectEstimate:
    """What the direct stage found: estimates of the fitted direct keys (play, load, drag),
    whether the flank changed (the play seen), the segments and the misfit [rad]."""

    values: dict[str, float]
    play_seen: bool
    segments: list[Segment]
    compliance: float
    misfit_rad: float
    flanks: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: When the segments' rates cannot separate the play from the drag (one rate each way:
    #: only b + 2 C c w is determined), the candidate value sets along that line, the
    #: play from small to the whole lag jump; :func:`best_on_family` picks one by simulation.
    family: list[dict[str, float]] = field(default_factory=list)
    #: A segment left out as floating in the play (torque near zero), and other consistent
    #: value sets the simulation should compare.
    floating: Segment | None = None
    alternatives: list[dict[str, float]] = field(default_factory=list)

    def describe(self) -> str:
        vals = ', '.join(f'{k} = {v:.4g}' for k, v in self.values.items())
        return (f'direct estimates from {len(self.segments)} constant-rate segments: {vals} '
                f'(misfit {self.misfit_rad:.3g} rad; play '
                f'{"seen" if self.play_seen else "not seen: one flank throughout"})')


def _solve(fixed: dict[str, float], free: Sequence[str], cols: dict[str, np.ndarray],
           e: np.ndarray, C: float) -> dict[str, float]:
    """The static lags' least squares for the keys ``free`` (play and drag >= 0, the load
    torque of either sign), the other direct keys at ``fixed``."""
    rhs = e - sum(cols[k] * fixed[k] for k in DIRECT_KEYS if k not in free)
    vals = dict(fixed)
    if free:
        A = np.column_stack([cols[k] for k in free])
        lo = [-np.inf if k == LOAD else 0.0 for k in free]
        sol = lsq_linear(A / C, rhs / C, bounds=(lo, [np.inf] * len(free))).x
        vals.update({k: float(v) for k, v in zip(free, sol)})
    return vals


def _separates_poorly(columns: Sequence[np.ndarray]) -> bool:
    """The columns (scaled to unit length) are nearly dependent: smallest singular value
    below 1e-3, e.g. the play and the drag from one rate each way."""
    A = np.column_stack([c / np.linalg.norm(c) for c in columns])
    return bool(np.linalg.svd(A, compute_uv=False)[-1] < 1e-3)


def _consistent(vals: dict[str, float], wg: np.ndarray, s: np.ndarray) -> bool:
    """The flank pattern ``s`` is what the torques give (a tolerance of 5 % of the largest
    torque, and TORQUE_TOL, for a segment near the switch)."""
    torque = vals[LOAD] + vals[DRAG] * wg
    tol = 0.05 * float(np.max(np.abs(torque))) + TORQUE_TOL
    return not np.any(torque * s < -tol)


def _misfit(vals: dict[str, float], s: np.ndarray, wg: np.ndarray, e: np.ndarray,
            C: float) -> float:
    pred = -s * 0.5 * vals[PLAY] - C * (vals[LOAD] + vals[DRAG] * wg)
    return float(np.sqrt(np.mean((pred - e) ** 2)))


@dataclass
class _Candidate:
    values: dict[str, float]
    misfit: float
    flanks: list[int]
    switch: bool
    family: list[dict[str, float]] = field(default_factory=list)
    floating: int | None = None


def _candidate(fitted: Sequence[str], fixed: dict[str, float], s_all: np.ndarray,
               keep: np.ndarray, wg_all: np.ndarray, e_all: np.ndarray, C: float
               ) -> _Candidate | None:
    """The flank equations on the kept segments for one flank pattern (None: the torques
    contradict the pattern)."""
    s, wg, e = s_all[keep], wg_all[keep], e_all[keep]
    m = s.size
    switch = bool(np.any(s > 0) and np.any(s < 0))
    cols = {PLAY: -0.5 * s, LOAD: -C * np.ones(m), DRAG: -C * wg}
    use = [k for k in fitted if not (k == PLAY and not switch)]
    flanks = [int(v) for v in s_all]
    if switch and PLAY in use and _separates_poorly([cols[k] for k in use]):
        # one rate each way: only b + 2 C c w is seen; the play along that line
        jump = float(np.mean(e[s < 0]) - np.mean(e[s > 0]))
        family = []
        for share in FAMILY_SHARES:
            vals = _solve(dict(fixed, **{PLAY: share * jump}),
                          [k for k in use if k != PLAY], cols, e, C)
            if _consistent(vals, wg, s):
                family.append(vals)
        if not family:
            return None
        mid = family[len(family) // 2]
        return _Candidate(mid, _misfit(mid, s, wg, e, C), flanks, switch, family)
    vals = _solve(fixed, use, cols, e, C)
    if not _consistent(vals, wg, s):
        return None
    return _Candidate(vals, _misfit(vals, s, wg, e, C), flanks, switch)


def _floating(c: _Candidate, fitted: Sequence[str], fixed: dict[str, float], drop: int,
              wg: np.ndarray, e: np.ndarray, C: float, wg_kept: np.ndarray
              ) -> _Candidate | None:
    """Segment ``drop`` floats in the play: its torque T + c w is near zero (within the
    consistency tolerance) and its lag lies between the flanks' wind-up lines.  When the kept
    segments hold one flank (only b / 2 + C T seen) the floating segment gives the load,
    T = -c w, and the play from that line.  None when the segment cannot float."""
    vals = dict(c.values)
    switch = c.switch
    if not switch and PLAY in fitted and LOAD in fitted:
        t_new = -vals[DRAG] * wg[drop]
        b = fixed[PLAY] + 2.0 * C * (vals[LOAD] - t_new)
        if not b > 0:
            return None
        vals.update({LOAD: float(t_new), PLAY: float(b)})
        switch = True
    torque = vals[LOAD] + vals[DRAG] * wg[drop]
    tol = 0.05 * float(np.max(np.abs(vals[LOAD] + vals[DRAG] * wg_kept))) + TORQUE_TOL
    if abs(torque) > tol or abs(e[drop] + C * torque) > 0.5 * vals[PLAY] + MISFIT_OK:
        return None
    return _Candidate(vals, c.misfit, c.flanks, switch, c.family, drop)


def _select(cands: Sequence[_Candidate]) -> _Candidate | None:
    """All segments on their flanks when that fits (misfit <= MISFIT_OK), else the smallest
    misfit, a floating segment allowed."""
    whole = [c for c in cands if c.floating is None]
    if whole:
        w = min(whole, key=lambda c: c.misfit)
        if w.misfit <= MISFIT_OK:
            return w
    return min(cands, key=lambda c: c.misfit) if cands else None


def simulated_rms(base: Config, records: Sequence[Record], vals: dict[str, float]) -> float:
    """RMS [rad] over all samples of the records' theta4 minus the simulation of ``base``
    with ``vals`` (inf when that set cannot be simulated)."""
    try:
        m = DriveModel(base.replace(vals))
        sq, n = 0.0, 0
        for r in records:
            if 'theta4' not in r.measured:
                continue
            d = predict(m, r)['theta4'] - r.measured['theta4']
            sq, n = sq + float(np.sum(d * d)), n + d.size
        return math.sqrt(sq / n) if n else math.inf
    except (ConfigError, SimulationError, ValueError):
        return math.inf


def best_of(base: Config, records: Sequence[Record], sets: Sequence[dict[str, float]]
            ) -> tuple[dict[str, float], list[dict[str, float]]]:
    """The value set whose simulation fits the records' theta4 best, and the table."""
    rows = [{**v, 'rms_rad': simulated_rms(base, records, v)} for v in sets]
    i = int(np.argmin([r['rms_rad'] for r in rows]))
    return dict(sets[i]), rows


def best_on_family(base: Config, records: Sequence[Record], family: Sequence[dict[str, float]]
                   ) -> tuple[dict[str, float], list[dict[str, float]]]:
    """The member of a direct estimate's family whose simulation fits the records' theta4
    best (RMS over all samples), refined once between its neighbours; and the table."""
    rows: list[dict[str, float]] = []

    def cost(vals: dict[str, float]) -> float:
        c = simulated_rms(base, records, vals)
        rows.append({**vals, 'rms_rad': c})
        return c

    costs = [cost(v) for v in family]
    i = int(np.argmin(costs))
    best, best_c = family[i], costs[i]
    for j in (i - 1, i + 1):            # halfway to each neighbour, twice
        if 0 <= j < len(family):
            for w in (0.5, 0.25):
                mid = {k: (1 - w) * family[i][k] + w * family[j][k] for k in family[i]}
                c = cost(mid)
                if c < best_c:
                    best, best_c = mid, c
    return best, rows


def direct_estimates(base: Config, records: Sequence[Record], keys: Sequence[str]
                     ) -> DirectEstimate | None:
    """Estimates of the keys among DIRECT_KEYS from the records' constant-rate segments
    (module docstring); None when the records hold fewer than two such segments or no
    direct key is fitted.  Keys not fitted keep their base values."""
    fitted = [k for k in DIRECT_KEYS if k in keys]
    if not fitted:
        return None
    model = DriveModel(base)
    u = model.output_per_input
    segs = [s for s in steady_segments(records, u)]
    if len(segs) < 2:
        return None
    C = compliance(base)
    wg = np.array([u * s.rate for s in segs])        # gear rate [rad/s]
    e = np.array([s.lag for s in segs])
    fixed = {PLAY: base.mesh.backlash, LOAD: base.load.output_torque,
             DRAG: base.load.output_viscous_coefficient}
    order = np.argsort(wg)
    cands: list[_Candidate] = []
    n = len(segs)
    # a segment may float in the play (its torque near zero: the gear between the flanks) and
    # is then left out of the flank equations, when >= 3 others remain
    drops: list[int | None] = [None] + (list(range(n)) if n >= 4 else [])
    for j in range(n + 1):           # segments below the j-th slowest: the coasting flank
        s_all = np.ones(n)
        s_all[order[:j]] = -1.0
        for drop in drops:
            keep = np.array([i != drop for i in range(n)])
            c = _candidate(fitted, fixed, s_all, keep, wg, e, C)
            if c is not None and drop is not None:
                c = _floating(c, fitted, fixed, drop, wg, e, C, wg[keep])
            if c is not None:
                cands.append(c)
    best = _select(cands)
    if best is None:
        return None
    mis, vals, flanks, switch = best.misfit, best.values, best.flanks, best.switch
    best_family = best.family
    alternatives = [c for c in cands if c is not best and c.floating is not None
                    and c.misfit <= max(MISFIT_OK, 1.5 * best.misfit)] \
        if best.floating is not None else []
    est = DirectEstimate({k: vals[k] for k in fitted}, switch, segs, C, mis, flanks,
                         family=[{k: v[k] for k in fitted} for v in best_family])
    if best.floating is not None:
        est.floating = segs[best.floating]
        est.alternatives = [{k: c.values[k] for k in fitted} for c in alternatives]
        est.notes.append(f'the {segs[best.floating].record} segment at '
                         f'{segs[best.floating].rate:+.3g} rad/s floats in the play (its '
                         'torque near zero): left out of the flank equations')
    if est.family:
        est.notes.append('one rate each way: the play and the drag are told apart by the '
                         'reversals\' transients only (a second rate would separate them)')
    if PLAY in fitted and not switch:
        est.notes.append('the gear stays on one flank in every constant-rate segment: the '
                         'play is not seen, only b / 2 + T C')
    return est


def scan_play(problem, x0: np.ndarray, index: int,
              factors: Sequence[float] = SCAN_FACTORS) -> tuple[np.ndarray, list[dict]]:
    """1-D scan of the play (fitted coordinate ``index`` of ``problem``, log scale) around
    ``x0`` on the time-domain cost of the whole records; returns the best x and the table."""
    p = problem.params[index]
    lo, hi = problem.x_bounds
    rows = []
    best_x, best_c = np.asarray(x0, float), math.inf
    for f in factors:
        x = np.asarray(x0, float).copy()
        x[index] = x[index] + (math.log(f) if p.log else (f - 1.0) * p.from_x(x0[index])
                               / p.scale)
        x[index] = min(max(x[index], lo[index]), hi[index])
        c = problem.cost(x)
        rows.append({'factor': f, 'value': p.from_x(float(x[index])), 'cost': c})
        if c < best_c:
            best_x, best_c = x, c
    return best_x, rows


def lag_table(segments: Sequence[Segment]) -> list[str]:
    """One line per segment (for reports)."""
    return [f'{s.record} {s.t0:.3f}-{s.t1:.3f} s: worm {s.rate:+.4g} rad/s, lag '
            f'{s.lag * 1e6:+.1f} urad' for s in segments]


