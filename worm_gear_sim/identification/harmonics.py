# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Identification of the periodic transmission error (``mesh.worm_error_harmonics``,
``mesh.gear_error_harmonics``) as linear parameters.

The coefficients are a linear least-squares problem given the nonlinear keys (variable
projection: a few passes reach the full model's fit); :func:`identify_with_harmonics`
alternates that with ``identify``.  docs/identification.md ("Periodic error harmonics").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config.usable import Config
from ..dynamics.model import DriveModel
from ..records import Record
from ..schema.sections import MAX_ERROR_ORDERS
from .data import IdentificationError, predict

__all__ = ['HarmonicFit', 'harmonic_names', 'harmonic_regressors', 'fit_harmonics',
           'identify_with_harmonics', 'parse_orders']

Z95 = 1.959963984540054
WORM_KEY, GEAR_KEY = 'mesh.worm_error_harmonics', 'mesh.gear_error_harmonics'
#: an interval narrower than this share of the largest coefficient: 'identified'
IDENTIFIED_SHARE = 0.05


def parse_orders(text: str) -> tuple[int, int]:
    """``worm:3,gear:1`` -> (3, 1) (a missing shaft: 0 orders); IdentificationError naming
    the bad part otherwise."""
    orders = {'worm': 0, 'gear': 0}
    for part in (p.strip() for p in str(text).split(',') if p.strip()):
        name, _, n = part.partition(':')
        if name not in orders or not n.strip().isdigit():
            raise IdentificationError(f'--fit-harmonics {text!r}: each part is worm:N or '
                                      f'gear:N (N orders), got {part!r}')
        orders[name] = int(n)
    for name, count in orders.items():
        if count > MAX_ERROR_ORDERS:
            raise IdentificationError(f'--fit-harmonics: {name}:{count}, at most '
                                      f'{MAX_ERROR_ORDERS} orders')
    if orders['worm'] + orders['gear'] == 0:
        raise IdentificationError(f'--fit-harmonics {text!r}: no order to fit')
    return orders['worm'], orders['gear']


def harmonic_names(worm_orders: int, gear_orders: int) -> list[str]:
    """Names of the coefficients in fitting order: ``mesh.worm_error_harmonics[0]`` (s1),
    ``[1]`` (c1), ... then the gear's."""
    return [f'{WORM_KEY}[{i}]' for i in range(2 * worm_orders)] + \
        [f'{GEAR_KEY}[{i}]' for i in range(2 * gear_orders)]


def harmonic_regressors(theta2: np.ndarray, theta3: np.ndarray, worm_orders: int,
                        gear_orders: int) -> np.ndarray:
    """Phi (n, 2 (worm_orders + gear_orders)): the columns sin k theta2, cos k theta2, ...,
    sin m theta3, cos m theta3 (the antenna's quasi-static response to each coefficient)."""
    cols = []
    for th, n in ((np.asarray(theta2, float), worm_orders),
                  (np.asarray(theta3, float), gear_orders)):
        for k in range(1, n + 1):
            cols += [np.sin(k * th), np.cos(k * th)]
    return np.column_stack(cols) if cols else np.empty((len(theta2), 0))


def _with(cfg: Config, c: np.ndarray, nw: int) -> Config:
    return cfg.replace({WORM_KEY: [float(v) for v in c[:2 * nw]],
                        GEAR_KEY: [float(v) for v in c[2 * nw:]]})


def _start(cfg: Config, nw: int, ng: int) -> np.ndarray:
    """The config's own coefficients of the fitted orders (zeros beyond them)."""
    out = []
    for key, n in ((WORM_KEY, nw), (GEAR_KEY, ng)):
        have = list(getattr(cfg.mesh, key.split('.')[1]))[:2 * n]
        out += have + [0.0] * (2 * n - len(have))
    return np.array(out, float)


@dataclass
class HarmonicFit:
    """The fitted coefficients with their 95 % intervals and verdicts (:func:`fit_harmonics`)."""

    names: list[str]
    values: np.ndarray
    ci95: list[tuple[float, float]]
    verdicts: dict[str, str]
    rms_before: float                     # [rad] residual of the output before / after
    rms_after: float
    passes: int
    config: Config = field(repr=False)
    nonlinear: Any = None                 # FitResult of the last nonlinear stage, or None

    def to_dict(self) -> dict[str, Any]:
        return {'harmonics': [{'key': n, 'estimate': float(v), 'ci95': list(ci),
                               'verdict': self.verdicts[n]}
                              for n, v, ci in zip(self.names, self.values, self.ci95)],
                'rms_before_rad': self.rms_before, 'rms_after_rad': self.rms_after,
                'passes': self.passes,
                'nonlinear': None if self.nonlinear is None else self.nonlinear.to_dict()}

    def table(self) -> str:
        lines = [f'{"harmonic":<34} {"estimate":>12} {"95 % CI":>27}  verdict']
        for n, v, (lo, hi) in zip(self.names, self.values, self.ci95):
            lines.append(f'{n:<34} {v:>12.4g} {f"{lo:.4g} .. {hi:.4g}":>27}  '
                         f'{self.verdicts[n]}')
        lines.append(f'residual RMS {self.rms_before:.3g} -> {self.rms_after:.3g} rad '
                     f'({self.passes} passes)')
        return '\n'.join(lines)


def _residuals(cfg: Config, records: Sequence[Record], output: str, nw: int, ng: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Stacked measured - predicted of ``output`` and the regressors at the model's angles."""
    model = DriveModel(cfg)
    rs, phis = [], []
    for rec in records:
        if output not in rec.measured:
            raise IdentificationError(f'record {rec.name or "?"} has no {output} to fit the '
                                      'harmonics to')
        pred = predict(model, rec)
        rs.append(np.asarray(rec.measured[output], float) - pred[output])
        phis.append(harmonic_regressors(pred['theta2'], pred['theta3'], nw, ng))
    return np.concatenate(rs), np.vstack(phis)


def fit_harmonics(base: Config, records: Sequence[Record], worm_orders: int,
                  gear_orders: int, output: str = 'theta4', max_passes: int = 6,
                  rtol: float = 1e-3) -> HarmonicFit:
    """Fit the first ``worm_orders`` / ``gear_orders`` harmonics of ``base`` (its other keys
    held) to ``output`` of the records (module docstring).  Starts from ``base``'s own
    coefficients; stops when a pass changes no coefficient by more than ``rtol`` of the
    largest (or after ``max_passes``)."""
    nw, ng = int(worm_orders), int(gear_orders)
    if not (0 <= nw <= MAX_ERROR_ORDERS and 0 <= ng <= MAX_ERROR_ORDERS) or nw + ng == 0:
        raise IdentificationError(f'harmonic orders worm {nw}, gear {ng}: 0..'
                                  f'{MAX_ERROR_ORDERS} each, at least one')
    if not records:
        raise IdentificationError('no records to fit the harmonics to')
    c = _start(base, nw, ng)
    cfg = _with(base, c, nw)
    r, phi = _residuals(cfg, records, output, nw, ng)
    rms_before = float(np.sqrt(np.mean(r ** 2)))
    passes = 0
    while passes < max_passes:
        passes += 1
        dc = np.linalg.lstsq(phi, r, rcond=None)[0]
        c = c + dc
        cfg = _with(base, c, nw)          # validated: the bounds and the slope limit
        r, phi = _residuals(cfg, records, output, nw, ng)
        if np.max(np.abs(dc)) <= rtol * max(np.max(np.abs(c)), 1e-300):
            break
    n, m = phi.shape
    s2 = float(r @ r) / max(n - m, 1)
    cov = s2 * np.linalg.pinv(phi.T @ phi)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    names = harmonic_names(nw, ng)
    ci = [(float(v - Z95 * s), float(v + Z95 * s)) for v, s in zip(c, std)]
    largest = float(np.max(np.abs(c)))
    verdicts = {}
    for name, s in zip(names, std):
        if Z95 * s <= IDENTIFIED_SHARE * largest:
            verdicts[name] = 'identified'
        else:
            verdicts[name] = (f'poorly determined: 95 % half-width {Z95 * s:.3g} rad, more '
                              f'than {100 * IDENTIFIED_SHARE:g} % of the largest coefficient '
                              '(record more worm or gear revolutions)')
    return HarmonicFit(names, c, ci, verdicts, rms_before, float(np.sqrt(np.mean(r ** 2))),
                       passes, cfg)


def identify_with_harmonics(base: Config, records: Sequence[Record], keys: Sequence[str],
                            worm_orders: int, gear_orders: int, *, rounds: int = 3,
                            output: str = 'theta4', options: Any = None,
                            bounds: Any = None) -> HarmonicFit:
    """Alternate the nonlinear ``keys`` (:func:`~worm_gear_sim.identification.fit.identify`,
    harmonics held) and the harmonics (:func:`fit_harmonics`, keys held) for ``rounds``
    rounds or until the harmonics settle (module docstring).  Without keys: the linear stage
    alone."""
    fit = fit_harmonics(base, records, worm_orders, gear_orders, output)
    if not keys:
        return fit
    from .fit import identify
    rms0 = fit.rms_before
    nonlinear = None
    for _ in range(int(rounds)):
        nonlinear = identify(fit.config, records, keys, bounds=bounds, options=options,
                             outputs=[output])
        previous = fit.values
        fit = fit_harmonics(nonlinear.config, records, worm_orders, gear_orders, output)
        if np.max(np.abs(fit.values - previous)) <= 1e-3 * max(
                float(np.max(np.abs(fit.values))), 1e-300):
            break
    fit.nonlinear = nonlinear
    fit.rms_before = rms0
    _joint_verdicts(fit, records, keys, worm_orders, gear_orders, output)
    return fit


#: |correlation| above this between a harmonic and a nonlinear key: not identifiable apart
CORRELATION_LIMIT = 0.98


def _joint_verdicts(fit: HarmonicFit, records: Sequence[Record], keys: Sequence[str],
                    nw: int, ng: int, output: str) -> None:
    """Intervals and verdicts of the harmonics from the joint linearisation [Phi, d
    output / d key] at the fit (each key's column by central differences of DIFF_STEP in
    its fitted coordinate): a harmonic the records cannot tell from a key (|correlation| >
    CORRELATION_LIMIT, e.g. a gear order over a small gear arc against the load torque's
    constant deflection) is 'not identifiable' and names it."""
    from .parameters import apply_values, fit_parameters
    from .problem import DIFF_STEP
    cfg = fit.config
    params = fit_parameters(cfg, list(keys))
    r, phi = _residuals(cfg, records, output, nw, ng)
    cols = []
    for prm in params:
        x0 = prm.to_x(prm.base)
        sides = []
        for sign in (1.0, -1.0):
            moved = apply_values(cfg, [prm], [prm.from_x(x0 + sign * DIFF_STEP)])
            sides.append(np.concatenate([predict(moved, rec)[output] for rec in records]))
        cols.append((sides[0] - sides[1]) / (2.0 * DIFF_STEP))
    J = np.column_stack([phi] + cols)
    n, m = J.shape
    s2 = float(r @ r) / max(n - m, 1)
    cov = s2 * np.linalg.pinv(J.T @ J)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(std, std)
    largest = float(np.max(np.abs(fit.values)))
    h = phi.shape[1]
    for i, name in enumerate(fit.names):
        v, si = float(fit.values[i]), float(std[i])
        fit.ci95[i] = (v - Z95 * si, v + Z95 * si)
        worst = max(range(h, m), key=lambda j: abs(corr[i, j]), default=None)
        if worst is not None and abs(corr[i, worst]) > CORRELATION_LIMIT:
            fit.verdicts[name] = (f'not identifiable: the records cannot tell it from '
                                  f'{params[worst - h].key} (correlation '
                                  f'{corr[i, worst]:+.3f}; record more gear rotation or fix '
                                  'the key)')
        elif Z95 * si <= IDENTIFIED_SHARE * largest:
            fit.verdicts[name] = 'identified'
        else:
            fit.verdicts[name] = (f'poorly determined: 95 % half-width {Z95 * si:.3g} rad, '
                                  f'more than {100 * IDENTIFIED_SHARE:g} % of the largest '
                                  'coefficient')


def largest_share_error(fitted: Sequence[float], truth: Sequence[float]) -> float:
    """max |fitted - truth| / max |truth| (the target measure of docs/identification.md)."""
    f, t = np.asarray(fitted, float), np.asarray(truth, float)
    return float(np.max(np.abs(f - t)) / max(np.max(np.abs(t)), 1e-300)) if t.size else \
        math.nan
