# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""What a fit means: estimates with 95 % confidence intervals from the Jacobian
(s^2 (J^T J)^-1, white-noise assumption), the correlation matrix (pairs above 0.95 flagged),
residual RMS per output before and after, and a verdict: a fit that did not converge, cannot
determine a parameter or leaves a residual far above the noise is marked not trustworthy,
with the reason.  Also the prediction error on held-out records (``--validate``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..dynamics.stepping import SimulationError
from ..records import Record
from .data import (
    FIT_EVERY,
    MAX_FIT_SAMPLES,
    OUTPUTS,
    RECORDED_SAMPLES,
    IdentificationError,
    normalised,
    predict,
    rigid_motion,
)
from .problem import DIFF_STEP, Problem, jacobian
from .visibility import key_visibility

__all__ = ['CORRELATION_WARN', 'Z95', 'FitResult', 'assess', 'residual_rms',
           'prediction_errors', 'validate', 'jsonable']

CORRELATION_WARN = 0.95
#: Lag-1 autocorrelation of an output's residuals above which they are not white: the model
#: misses something the parameters cannot cover, and the intervals (which assume white
#: residuals and an exact model) are too narrow.
RESIDUAL_AUTOCORRELATION_WARN = 0.5
Z95 = 1.959963984540054
#: A Jacobian column that changes by more than this between the steps h and 4 h is not
#: resolved at h: the parameter's effect is at the level of the stick-slip decisions' noise.
STEP_CONSISTENCY_WARN = 0.1
#: Steps tried for such a column: DIFF_STEP * 4^k up to this (in the fitted coordinate).
MAX_JACOBIAN_STEP = 0.3


@dataclass
class FitResult:
    """Estimates, uncertainty, residuals and verdict of :func:`identify` (``to_dict`` for
    JSON)."""

    keys: list[str]
    units: list[str]
    base_values: list[float]
    values: list[float]
    ci95: list[tuple[float, float]]
    std_x: list[float]                    # standard deviation in the fitted coordinate
    log_scale: list[bool]
    correlation: list[list[float]]
    rms_before: dict[str, float]          # [rad], pooled over the records
    rms_after: dict[str, float]
    scale: dict[str, float]               # [rad] residual scale per output
    noise: dict[str, float]               # [rad] white-noise estimate per output
    per_record: list[dict[str, Any]]
    cost: float
    converged: bool
    trustworthy: bool
    problems: list[str]                   # why it is not trustworthy
    warnings: list[str]
    strategy: dict[str, Any]
    starts: list[dict[str, Any]]
    frequency_info: dict[str, Any]
    seconds: float
    config: Config = field(repr=False)
    base_config: Config = field(repr=False)
    step_consistency: list[float] = field(default_factory=list)
    jacobian_steps: list[float] = field(default_factory=list)
    #: every measured output: 'matched', 'not matched: ...', or why it was not fitted
    #: ('... not observable at this sampling ...', 'not fitted ...')
    output_verdicts: dict[str, str] = field(default_factory=dict)
    #: fitted keys the records cannot show: key -> one line naming it and the move to record
    not_seen: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            'parameters': [
                {'key': k, 'unit': u, 'base': b, 'estimate': v, 'ci95': list(ci),
                 'log_scale': lg, 'std_fitted_coordinate': s, 'jacobian_step': h,
                 'jacobian_step_change': sc}
                for k, u, b, v, ci, lg, s, h, sc in zip(
                    self.keys, self.units, self.base_values, self.values, self.ci95,
                    self.log_scale, self.std_x,
                    self.jacobian_steps or [math.nan] * len(self.keys),
                    self.step_consistency or [math.nan] * len(self.keys))],
            'correlation': self.correlation, 'rms_before_rad': self.rms_before,
            'rms_after_rad': self.rms_after, 'residual_scale_rad': self.scale,
            'noise_estimate_rad': self.noise,
            'records': self.per_record, 'cost': self.cost, 'converged': self.converged,
            'trustworthy': self.trustworthy, 'problems': self.problems,
            'warnings': self.warnings, 'strategy': self.strategy, 'starts': self.starts,
            'frequency_start': self.frequency_info, 'seconds': self.seconds,
            'output_verdicts': self.output_verdicts, 'not_seen': self.not_seen,
        }

    def table(self) -> str:
        lines = [f'{"parameter":<44} {"base":>12} {"estimate":>12} {"95 % CI":>27}  unit']
        for k, u, b, v, (lo, hi) in zip(self.keys, self.units, self.base_values, self.values,
                                        self.ci95):
            lines.append(f'{k:<44} {b:>12.6g} {v:>12.6g} [{lo:>11.6g}, {hi:>11.6g}]  {u}')
        if self.output_verdicts:
            lines.append('outputs: ' + '; '.join(
                v if v.startswith(o) else f'{o}: {v}' for o, v in self.output_verdicts.items()))
        lines.append('residual RMS per output [rad] (before -> after, % of the residual scale):')
        for o in self.rms_after:
            s = self.scale[o]
            lines.append(f'  {o}: {self.rms_before[o]:.4g} -> {self.rms_after[o]:.4g} '
                         f'({100 * self.rms_before[o] / s:.1f} % -> '
                         f'{100 * self.rms_after[o] / s:.2f} %; noise level '
                         f'{self.noise[o]:.3g})')
        if len(self.keys) > 1:
            lines.append('correlation:')
            for k, row in zip(self.keys, self.correlation):
                lines.append(f'  {k:<44} ' + ' '.join(f'{c:+.3f}' for c in row))
        for w in self.warnings:
            lines.append(f'WARNING: {w}')
        for p in self.problems:
            lines.append(f'NOT TRUSTWORTHY: {p}')
        return '\n'.join(lines)


def residual_autocorrelation(problem: Problem, x: np.ndarray) -> dict[str, float]:
    """Lag-1 autocorrelation of each fitted output's residuals (pooled over the records,
    within each record)."""
    model = DriveModel(problem.config(x))
    num: dict[str, float] = {o: 0.0 for o in problem.outputs}
    den: dict[str, float] = {o: 0.0 for o in problem.outputs}
    for r in problem.records:
        try:
            pred = predict(model, r)
        except (SimulationError, ValueError):
            continue
        for o in problem.outputs:
            if o not in r.measured:
                continue
            e = pred[o] - r.measured[o]
            e = e - e.mean()
            num[o] += float(e[1:] @ e[:-1])
            den[o] += float(e @ e)
    return {o: num[o] / den[o] for o in problem.outputs if den[o] > 0}


def residual_rms(problem: Problem, model: DriveModel | Config
                 ) -> tuple[dict[str, float], list[dict[str, Any]]]:
    """Pooled and per-record RMS of predicted - measured [rad] per output."""
    model = DriveModel.of(model)
    pooled: dict[str, list[np.ndarray]] = {o: [] for o in problem.outputs}
    per = []
    for r in problem.records:
        try:
            pred = predict(model, r)
        except (SimulationError, ValueError):
            pred = None
        row: dict[str, Any] = {'name': r.name}
        for o, meas in r.measured.items():
            e = (pred[o] - meas) if pred is not None else np.full(meas.size, np.nan)
            pooled[o].append(e)
            row[o] = float(np.sqrt(np.mean(e ** 2)))
        per.append(row)
    return ({o: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for o, v in pooled.items()},
            per)


def resolved_jacobian(problem: Problem, x: np.ndarray
                      ) -> tuple[np.ndarray, list[float], list[float]]:
    """The report's Jacobian at ``x`` (central differences over the whole records), each
    column taken with the smallest step h = DIFF_STEP * 4^k whose column agrees with the one
    at 4 h within STEP_CONSISTENCY_WARN (relative norm of the difference): a smooth
    parameter keeps DIFF_STEP, one whose effect is near the noise of the stick-slip decisions
    gets a step that sees through it.  Returns (J, step per column, relative change between
    the chosen step and 4 times it; above STEP_CONSISTENCY_WARN when no step up to
    MAX_JACOBIAN_STEP was consistent, the column of the largest step is used)."""
    h = DIFF_STEP
    J = jacobian(problem, x, h)
    n = J.shape[1]
    steps, change = [h] * n, [math.inf] * n
    todo = list(range(n))
    while todo and 4 * h <= MAX_JACOBIAN_STEP:
        J4 = jacobian(problem, x, 4 * h, columns=todo)
        for i in list(todo):
            nrm = float(np.linalg.norm(J4[:, i]))
            c = float(np.linalg.norm(J[:, i] - J4[:, i])) / nrm if nrm > 0 else math.inf
            if c <= STEP_CONSISTENCY_WARN or 16 * h > MAX_JACOBIAN_STEP:
                change[i] = c
                if c > STEP_CONSISTENCY_WARN:
                    J[:, i], steps[i] = J4[:, i], 4 * h
                todo.remove(i)
            else:
                J[:, i], steps[i] = J4[:, i], 4 * h
        h *= 4
    return J, steps, change


def assess(problem: Problem, results: Sequence[dict[str, Any]], max_nfev: int
           ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The statistics and the verdict of the best of ``results`` (local fits, each with
    ``x``, ``cost``, ``status``, ``message``, ``converged``, ``stages``, ``index``): returns
    (best, fields of :class:`FitResult` other than strategy, starts, frequency_info and
    seconds)."""
    params = problem.params
    best = min(results, key=lambda r: r['cost'] if math.isfinite(r['cost']) else np.inf)
    problems: list[str] = []
    est = _Estimate.at(problem, np.asarray(best['x'], float), problems)
    model_fit = DriveModel(problem.config(est.x))
    rms_before, per_before = residual_rms(problem, problem.base)
    rms_after, per_after = residual_rms(problem, model_fit)
    per_record = [{'name': a['name'],
                   'rms_before_rad': {k: v for k, v in a.items() if k != 'name'},
                   'rms_after_rad': {k: v for k, v in b.items() if k != 'name'}}
                  for a, b in zip(per_before, per_after)]
    converged = bool(best['converged'])
    if not converged:
        problems.append(f'the fit did not converge within {max_nfev} evaluations '
                        f'({best["message"]}; the cost still fell by '
                        f'{best["stages"][-1]["last_decrease"]:.3g} over the last ones)')
    warnings: list[str] = []
    verdicts = _output_verdicts(problem, rms_before, rms_after, problems, warnings)
    warnings += _autocorrelation_warnings(problem, est.x)
    warnings += _correlation_warnings(problem, est.corr)
    # which keys the records cannot show, judged with the fitted values (the play, load and
    # drag the fit found), one line each naming the move to record
    not_seen = key_visibility(model_fit.config, problem.records, [p.key for p in params])
    warnings.extend(not_seen.values())
    warnings += _parameter_warnings(problem, est)
    warnings += _second_minimum(problem, results, best, est)
    corr = est.corr
    return best, dict(
        keys=[p.key for p in params], units=[p.unit for p in params],
        base_values=[p.base for p in params], values=est.values, ci95=est.ci,
        std_x=[float(s) for s in est.std], log_scale=[p.log for p in params],
        correlation=np.where(np.isfinite(corr), corr, np.nan).tolist(),
        rms_before=rms_before, rms_after=rms_after, scale=dict(problem.scale),
        noise=dict(problem.noise), per_record=per_record,
        cost=float(0.5 * est.r @ est.r),
        converged=converged, trustworthy=not problems, problems=problems,
        warnings=warnings + list(problem.left_out.values()) + _thinning_notes(problem),
        output_verdicts={o: verdicts.get(o) or problem.left_out[o]
                         for o in OUTPUTS if o in verdicts or o in problem.left_out},
        config=model_fit.config, base_config=problem.base, not_seen=not_seen,
        step_consistency=[float(s) for s in est.step_change], jacobian_steps=est.steps)


@dataclass
class _Estimate:
    """The estimate ``x`` with its Jacobian, residuals, covariance and 95 % intervals."""

    x: np.ndarray
    J: np.ndarray
    steps: list[float]
    step_change: list[float]
    r: np.ndarray
    s2: float
    std: np.ndarray
    corr: np.ndarray
    values: list[float]
    ci: list[tuple[float, float]]

    @classmethod
    def at(cls, problem: Problem, x: np.ndarray, problems: list[str]) -> _Estimate:
        """The statistics at ``x``; a singular Jacobian is added to ``problems``."""
        params, n = problem.params, problem.n
        # Jacobian at the estimate (full records) for the uncertainty; least_squares' own
        # jac is scaled by the distance to active bounds and unusable for that.
        J, steps, step_change = resolved_jacobian(problem, x)
        r = problem.residuals(x)
        s2 = float(r @ r) / max(r.size - n, 1)
        U, sv, Vt = np.linalg.svd(J, full_matrices=False)
        rank_tol = sv[0] * 1e-10 if sv.size and sv[0] > 0 else 0.0
        if sv.size == 0 or sv[-1] <= rank_tol:
            weakest = params[int(np.argmax(np.abs(Vt[-1])))].key if sv.size else '?'
            problems.append(f'the data do not determine {weakest} (singular Jacobian)')
            cov = np.full((n, n), np.nan)
        else:
            cov = s2 * (Vt.T / sv ** 2) @ Vt
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(invalid='ignore', divide='ignore'):
            corr = cov / np.outer(std, std)
        values, ci = [], []
        for p, xi, si in zip(params, x, std):
            values.append(p.from_x(float(xi)))
            if not math.isfinite(si):
                ci.append((math.nan, math.nan))
            else:
                ci.append((p.from_x(xi - Z95 * si), p.from_x(xi + Z95 * si)))
        return cls(x, J, steps, step_change, r, s2, std, corr, values, ci)


def _output_verdicts(problem: Problem, rms_before: dict[str, float],
                     rms_after: dict[str, float], problems: list[str],
                     warnings: list[str]) -> dict[str, str]:
    """Whether the fitted model matches each output; mismatches go to ``problems``."""
    verdicts: dict[str, str] = {}
    for o in problem.outputs:
        rel = rms_after[o] / problem.scale[o]
        verdicts[o] = 'matched'
        if not math.isfinite(rel):
            problems.append(f'the fitted model cannot be simulated on every record ({o})')
            verdicts[o] = 'not matched: the fitted model cannot be simulated on every record'
        elif rel > 0.25 and rms_after[o] > 3.0 * problem.noise[o]:
            problems.append(f'{o}: residual RMS {100 * rel:.0f} % of the measured motion '
                            f'(> 25 %) and {rms_after[o] / max(problem.noise[o], 1e-300):.1f}'
                            ' x the noise level: the model does not match the records')
            verdicts[o] = f'not matched: residual RMS {100 * rel:.0f} % of the measured motion'
        elif rms_after[o] > rms_before[o] * 1.0001:
            warnings.append(f'{o}: residual RMS grew ({rms_before[o]:.3g} -> '
                            f'{rms_after[o]:.3g} rad)')
    return verdicts


def _autocorrelation_warnings(problem: Problem, x: np.ndarray) -> list[str]:
    """Outputs whose residuals are correlated: the model misses something."""
    return [f'{o}: the residuals are correlated (lag-1 autocorrelation '
            f'{rho:.2f}): the model misses something no fitted parameter '
            'covers, so the 95 % parameter intervals (which assume an exact '
            'model and white residuals) are too narrow and not meaningful; '
            'judge the fit by its held-out prediction error and the '
            'prediction bound (calibrate)'
            for o, rho in residual_autocorrelation(problem, x).items()
            if rho > RESIDUAL_AUTOCORRELATION_WARN]


def _correlation_warnings(problem: Problem, corr: np.ndarray) -> list[str]:
    """Pairs of parameters the data can hardly separate."""
    params, out = problem.params, []
    for i in range(problem.n):
        for j in range(i + 1, problem.n):
            c = corr[i, j]
            if math.isfinite(c) and abs(c) > CORRELATION_WARN:
                out.append(f'{params[i].key} and {params[j].key} are correlated '
                           f'({c:+.3f}): the data can hardly separate them')
    return out


def _parameter_warnings(problem: Problem, est: _Estimate) -> list[str]:
    """Each parameter on a bound, unresolved or hardly determined."""
    out = []
    for p, v, (clo, chi), si, sc, h in zip(problem.params, est.values, est.ci, est.std,
                                           est.step_change, est.steps):
        bx = p.x_bounds
        xi = p.to_x(v)
        if (math.isfinite(bx[0]) and xi - bx[0] < 1e-6) or \
                (math.isfinite(bx[1]) and bx[1] - xi < 1e-6):
            out.append(f'{p.key} = {v:.6g} sits on a bound: the optimum may lie outside')
        if not (sc <= STEP_CONSISTENCY_WARN):
            out.append(f'{p.key}: its effect on the residuals is not resolved (the '
                       'finite-difference sensitivity still changes by '
                       f'{100 * sc:.0f} % between steps {h / 4:g} and {h:g}): the data '
                       'hardly see it beside the stick-slip decisions of the friction '
                       'law; its interval is not reliable')
        elif math.isfinite(si) and p.log and si > 0.5:
            out.append(f'{p.key}: 95 % interval {clo:.3g} .. {chi:.3g} spans more than '
                       f'a factor {math.exp(2 * Z95 * 0.5):.0f}: hardly determined by the '
                       'data (its value in the YAML is arbitrary; fix it or record a move '
                       'that excites it)')
        elif math.isfinite(si) and not p.log and Z95 * si * p.scale > max(abs(v), p.scale):
            out.append(f'{p.key}: 95 % interval {clo:.3g} .. {chi:.3g} is wider than the '
                       'value: poorly determined')
    return out


def _second_minimum(problem: Problem, results: Sequence[dict[str, Any]],
                    best: dict[str, Any], est: _Estimate) -> list[str]:
    """Another start that fits statistically as well (cost within the 95 % confidence
    region, 0.5 s^2 chi2(0.95, n)) but lies far outside the linearised region (Mahalanobis
    distance > 2 sqrt(chi2)): a second minimum, the optimum is not unique."""
    c95 = float(chi2.ppf(0.95, problem.n))
    JtJ = est.J.T @ est.J
    for rr in results:
        if rr is best or not math.isfinite(rr['cost']):
            continue
        dx = np.asarray(rr['x']) - est.x
        if rr['cost'] - best['cost'] <= 0.5 * est.s2 * c95 and \
                float(dx @ JtJ @ dx) / est.s2 > 4.0 * c95:
            far = [f'{p.key} = {p.from_x(float(xi)):.4g}' for p, xi, d, si in
                   zip(problem.params, rr['x'], dx, est.std)
                   if abs(d) > 2 * Z95 * max(si, 1e-300)]
            return [f'start {rr["index"] + 1} fits as well with '
                    f'{", ".join(far) or "other values"}: the data do not fix '
                    'these values (both fit the records equally well)']
    return []


def _thinning_notes(problem: Problem) -> list[str]:
    """Records the fit thinned to at most MAX_FIT_SAMPLES samples."""
    return [f'{r.name}: the fit kept every {r.source[FIT_EVERY]}th sample ({len(r.t)} of '
            f'{r.source[RECORDED_SAMPLES]}; at most {MAX_FIT_SAMPLES} per record)'
            for r in problem.records if r.source.get(FIT_EVERY, 1) > 1]


# ---- validation on held-out records ------------------------------------------------------------
def prediction_errors(cfg: DriveModel | Config, records: Sequence[Record]
                      ) -> list[dict[str, Any]]:
    """Per record and measured output: RMS of predicted - measured [rad], the oscillation
    amplitude (half the peak-to-peak range of the measured angle minus the rigid motion
    theta1 * u_rigid [rad]) and their ratio ``rel``."""
    model = DriveModel.of(cfg)
    rigid = rigid_motion(model)
    out = []
    for i, rec in enumerate(records):
        rr = normalised(rec, i)
        try:
            pred = predict(model, rr)
        except SimulationError as exc:
            raise IdentificationError(f'{rr.name}: the model cannot be simulated ({exc})'
                                      ) from None
        row: dict[str, Any] = {'name': rr.name}
        for o, meas in rr.measured.items():
            e = pred[o] - meas
            amp = 0.5 * float(np.ptp(meas - rigid[OUTPUTS.index(o)] * rr.theta1))
            rms = float(np.sqrt(np.mean(e ** 2)))
            row[o] = {'rms_rad': rms, 'amplitude_rad': amp,
                      'rel': rms / amp if amp > 0 else math.inf}
        out.append(row)
    return out


def validate(cfg: DriveModel | Config, records: Sequence[Record]) -> list[dict[str, Any]]:
    """Alias of :func:`prediction_errors` (the ``--validate`` report)."""
    return prediction_errors(cfg, records)


def jsonable(obj: Any) -> Any:
    """``obj`` for ``json.dumps``: keys as strings, tuples as lists, numpy scalars as Python
    numbers, a float that is not finite as None (a report's JSON)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if hasattr(obj, 'item'):
        return jsonable(obj.item())
    return obj
