# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Is a parameter set *usable*: the rules behind ``check_usable`` and :func:`diagnose` (a
failed integration's likely cause).

A set whose every field is in range may still not simulate; the rules (the mesh stiffness
over a cycle, the spring chain holding every body, the modes, a short trial run) each name
the parameters that set them.  Cost: ``python benchmarks/bench_usable.py``.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._support.stepwise import Steps, run_steps
from ..schema.parameters import Parameters
from ..schema.sections import ANGLE_LIMIT
from ..schema.validation import ConfigError

if TYPE_CHECKING:
    from .model import DriveModel

__all__ = ['check_usable', 'check_usable_steps', 'usable_model', 'diagnose',
           'SPRING_RATIO_MIN', 'OMEGA_DT_MAX', 'TRIAL_TIME']

#: Two springs on one body: the smaller must be at least this share of the larger (it keeps
#: 7 significant digits in their sum).
SPRING_RATIO_MIN = 1e-9
#: Highest linearised mode times the time step (pi: two steps per period).
OMEGA_DT_MAX = math.pi
#: Trial integration: a ramp of TRIAL_ANGLE over the first half, then held.
TRIAL_TIME = 2e-3
TRIAL_ANGLE = 0.0113

_WORM_SHAFT = ('materials.worm_shaft_shear_modulus', 'shafts.worm_shaft_radius',
               'shafts.worm_shaft_length')
_GEAR_SHAFT = ('materials.gear_shaft_shear_modulus', 'shafts.gear_shaft_radius',
               'shafts.gear_shaft_length')
_TEETH = {
    'worm': ('mesh.worm_fit_b', 'mesh.worm_fit_a', 'mesh.worm_tooth_stiffness_linear',
             'mesh.worm_tooth_stiffness_multiplier', 'geometry.module'),
    'gear': ('mesh.gear_fit_b', 'mesh.gear_fit_a', 'mesh.gear_tooth_stiffness_linear',
             'mesh.gear_tooth_stiffness_multiplier', 'geometry.module'),
}
_MESH = ('shafts.worm_bearing_axial_stiffness', 'shafts.gear_bearing_axial_stiffness',
         'materials.youngs_modulus', 'geometry.pressure_angle', 'geometry.lead_angle',
         'geometry.lead', 'geometry.worm_pitch_radius', 'geometry.gear_pitch_radius')
_INERTIA = {
    0: ('geometry.worm_length', 'geometry.worm_pitch_radius', 'materials.worm_density',
        'shafts.worm_shaft_inertia_fraction'),
    1: ('geometry.gear_width', 'geometry.gear_pitch_radius', 'materials.gear_density',
        'shafts.gear_shaft_inertia_fraction'),
    2: ('geometry.flywheel_length', 'geometry.flywheel_radius', 'materials.flywheel_density',
        'geometry.shaft_end_inertia', 'shafts.gear_shaft_inertia_fraction'),
}


def check_usable(cfg: Parameters, changed: Iterable[str] | None = None) -> None:
    """Raise :class:`ConfigError` unless ``cfg`` can be simulated (see the module doc).

    ``changed``: the dotted keys just set (``Config.replace``); they are named first, and
    alone when a failure has no rule of its own.  Without it, the keys that differ from the
    defaults are named.  A usable Config is remembered (Configs are immutable), so checking
    it again is a dictionary look-up."""
    run_steps(check_usable_steps(cfg, changed))


def check_usable_steps(cfg: Parameters, changed: Iterable[str] | None = None) -> Steps[None]:
    """:func:`check_usable` in steps (:mod:`worm_gear_sim._support.stepwise`: the node prepares an
    adapted set a slice at a time); numpy's floating-point errors are ignored inside each
    step only, never in the caller's code between them."""
    if cfg in _USABLE:
        return
    keys = tuple(changed) if changed is not None else _differs_from_defaults(cfg)
    steps = _check(cfg, keys)
    while True:
        try:
            with np.errstate(all='ignore'):     # a bad set fails below, silently
                next(steps)
        except StopIteration as stop:
            model = stop.value
            break
        except ConfigError:
            raise
        except (ArithmeticError, ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
            raise _blame(cfg, keys, (), f'not computable ({type(exc).__name__}: {exc})') \
                from None
        yield
    with _LOCK:                             # the node's worker thread and its executor
        if len(_USABLE) >= _CACHE_SIZE:
            _USABLE.pop(next(iter(_USABLE)), None)
        _USABLE[cfg] = True
        if len(_MODELS) >= _MODEL_CACHE_SIZE:
            _MODELS.pop(next(iter(_MODELS)), None)
        _MODELS[cfg] = model


def usable_model(cfg: Parameters) -> DriveModel:
    """The :class:`DriveModel` of ``cfg``, proven usable (:func:`check_usable`): the model the
    check itself built when it checked ``cfg`` recently (a fit's every candidate is a new
    set, checked by ``Config.replace`` and then simulated: built once instead of twice),
    else a new one.  Models are immutable, so sharing one changes no number."""
    model = _MODELS.get(cfg)
    if model is None:
        check_usable(cfg)
        model = _MODELS.get(cfg)
    if model is None:                       # checked long ago, or evicted since
        from .model import DriveModel
        model = DriveModel(cfg)
    return model


_CACHE_SIZE = 512
_USABLE: dict[Parameters, bool] = {}
#: the models of the last sets checked (a fit's Jacobian columns and starts run at once)
_MODEL_CACHE_SIZE = 16
_MODELS: dict[Parameters, DriveModel] = {}
_LOCK = threading.Lock()
# a forked child (dynamics.forked) gets the caches whole, never half-updated, and a free lock
os.register_at_fork(before=_LOCK.acquire, after_in_parent=_LOCK.release,
                    after_in_child=_LOCK.release)


def _differs_from_defaults(cfg: Parameters) -> tuple[str, ...]:
    ref = Parameters().to_flat_dict()
    return tuple(k for k, v in cfg.to_flat_dict().items() if ref[k] != v)


def _blame(cfg: Parameters, changed: Sequence[str], suspects: Sequence[str],
           why: str) -> ConfigError:
    """ConfigError on the most likely key: the changed suspects, else the changed keys, else
    the first suspect.  The message shows their values; ``keys`` holds all of them."""
    flat = cfg.to_flat_dict()
    named = [k for k in suspects if k in changed] or list(changed) or list(suspects[:1])
    head = ', '.join(f'{k} = {flat[k]!r}' for k in named if k in flat)
    err = ConfigError(named[0] if named else '', why, keys=named)
    if head:
        err.args = (f'{head}: {why}',)
    return err


def _check(cfg: Parameters, changed: Sequence[str]) -> Steps[DriveModel]:
    """The rules (module doc), in steps; returns the model it built and ran."""
    subject = _Subject(cfg, changed, _built_model(cfg, changed))
    yield
    for rule in _RULES:
        yield from rule(subject)
    return subject.model


@dataclass
class _Subject:
    """The set under check, the keys just changed, its model and (after rule 3) its modes:
    natural frequencies [Hz] and shapes."""

    cfg: Parameters
    changed: Sequence[str]
    model: DriveModel
    modes: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty((0, 0)))

    def blame(self, suspects: Sequence[str], why: str) -> ConfigError:
        return _blame(self.cfg, self.changed, suspects, why)

    @property
    def fit_b(self) -> dict[str, float]:
        """The exponents of Eqs. 16-17."""
        return {'worm': self.cfg.mesh.worm_fit_b, 'gear': self.cfg.mesh.gear_fit_b}

    def cycle_states(self) -> list[tuple[float, float]]:
        """(theta2, theta3) at the mesh phases where the contact position x(s) takes its
        extremes: 0 and 180 deg (cosine mapping) or 0 and 360 deg (sawtooth)."""
        two_pi = 2.0 * math.pi
        # theta2 = 2 (phase - phase_offset) with theta3 = 0 gives that mesh phase
        return [(2.0 * (phase - self.cfg.mesh.phase_offset), 0.0)
                for phase in (0.0, 0.5 * two_pi, two_pi * (1.0 - 1e-12))]


def _built_model(cfg: Parameters, changed: Sequence[str]) -> DriveModel:
    """The set's model; a calibration of Eqs. 16-17 that overflows blames the b's."""
    from .model import DriveModel
    try:
        return DriveModel(cfg)
    except (ArithmeticError, ValueError):
        # the calibration of Eqs. 16-17 overflows: e^{360 b} too steep
        b_keys = [k for k in ('mesh.worm_fit_b', 'mesh.gear_fit_b') if k in changed] \
            or ['mesh.worm_fit_b', 'mesh.gear_fit_b']
        raise _blame(cfg, changed, b_keys, 'the tooth stiffness of Eqs. 16-17 varies by '
                     'e^(360 |b|) over a mesh cycle; this b makes it overflow (the '
                     'paper: |b| < 0.001 1/deg, a factor 1.3)') from None


def _rule_tooth_stiffness(s: _Subject) -> Steps[None]:
    """Rule 1: tooth stiffness over the cycle, finite and > 0.  Eqs. 16-17 are
    exponentials of the contact position x(s): evaluated where x takes its extremes."""
    from .equations import tooth_stiffness
    model = s.model
    linear = model.mesh_is_linear
    if not math.isfinite(model.linear_mesh_compliance):
        raise s.blame(_TEETH['worm'][2:] + _TEETH['gear'][2:4],
                      'the linear tooth compliance 1/c_w k_w + 1/c_g k_g (Eq. 7) overflows: '
                      'a tooth stiffness this small is no mesh')
    for i, side in enumerate(('worm', 'gear')):
        vals = [tooth_stiffness(model.p, th2, th3)[i] for th2, th3 in s.cycle_states()]
        if linear:
            vals = [model.linear_tooth_stiffness[i]]
        lo, hi = min(vals), max(vals)
        if not (math.isfinite(hi) and lo > 0.0 and math.isfinite(lo)):
            sym = 'c_w k_w' if side == 'worm' else 'c_g k_g'
            why = (f'the {side} tooth stiffness {sym} (Eq. {16 if side == "worm" else 17}) '
                   f'spans {lo:.3g} .. {hi:.3g} N/m over a mesh cycle')
            if not linear:
                factor = math.exp(min(700.0, 360 * abs(s.fit_b[side])))
                why += f' (a factor e^(360 |b|) = {factor:.3g})'
            raise s.blame(_TEETH[side], why + ': it must stay finite and > 0')
    yield from ()                           # a check in one step: no pause


def _rule_spring_chain(s: _Subject) -> Steps[None]:
    """Rule 2: the spring chain holds every body, at both ends of the cycle.  Seen from the
    motor, each body is held by the springs between it and the motor (in series); if that
    holding stiffness is lost next to the spring leading further out, the pivot of the
    stiffness matrix at the next body cancels to 0: singular."""
    from .equations import mesh_stiffness_y
    d, b_fit = s.model.derived, s.fit_b
    Kw, Kg, lw, rg = d.K_w, d.K_g, d.l_w, s.cfg.geometry.gear_pitch_radius
    variation = '' if s.model.mesh_is_linear else (
        'over a mesh cycle the tooth stiffnesses of Eqs. 16-17 vary by e^(360 |b|) = '
        f'{math.exp(min(700.0, 360 * abs(b_fit["worm"]))):.3g} (worm), '
        f'{math.exp(min(700.0, 360 * abs(b_fit["gear"]))):.3g} (gear); at its weakest ')
    mesh_keys = _TEETH['worm'] + _TEETH['gear'][:4] + _MESH
    for th2, th3 in s.cycle_states():
        kY = mesh_stiffness_y(s.model.p, th2, th3)
        springs = {'worm shaft K_w': (Kw, _WORM_SHAFT), 'mesh l_w^2 k_Y': (lw * lw * kY,
                                                                             mesh_keys),
                   'gear shaft K_g': (Kg * (lw / rg) ** 2, _GEAR_SHAFT)}  # at the worm
        for name, (k, keys) in springs.items():
            if not (math.isfinite(k) and k > 0.0):
                raise s.blame(keys, f'the {name} stiffness is {k:.3g} N m/rad '
                              '(seen at the worm): it must be finite and > 0')
        held, inner = Kw, 'worm shaft K_w'
        for outer in ('mesh l_w^2 k_Y', 'gear shaft K_g'):
            k_out = springs[outer][0]
            if held < SPRING_RATIO_MIN * k_out:
                why = variation if 'mesh' in inner else ''
                raise s.blame(springs[inner][1], why +
                              f'the {inner} = {springs[inner][0]:.3g} N m/rad (seen at the '
                              f'worm) is below {SPRING_RATIO_MIN:g} of the {outer} = '
                              f'{k_out:.3g} beyond it: in double precision the drive is no '
                              'longer held (singular stiffness matrix)')
            held = 1.0 / (1.0 / held + 1.0 / k_out)      # in series, now out to `outer`
            if k_out < springs[inner][0]:
                inner = outer                               # the weakest spring so far
    yield from ()                           # a check in one step: no pause


def _rule_modes(s: _Subject) -> Steps[None]:
    """Rule 3: the modes are computable, damped as :func:`~.modal.modes` gives them to its
    users (the compensator's antenna mode, the diagnosis of a failing trial): an
    undamped eigenproblem can succeed where the damped pencil has no finite eigenvalue.
    Rule 3b: the step resolves every mode (at least 2 steps per period).  The implicit
    step exists beyond that (average acceleration is stable at any step) and a short trial
    may pass, but Newton cannot follow the nonlinear mesh through a mode it steps over:
    a set with its highest mode at 3.8 GHz passed the trial and then failed 25 893 times
    live.  Between 2 and STEPS_PER_PERIOD steps per period is allowed with a warning."""
    from .modal import modes_steps
    yield
    full = yield from modes_steps(s.model)
    s.modes = (full.undamped_hz, full.shapes)
    if not np.all(np.isfinite(s.modes[0])):
        raise s.blame((), 'the linearised natural frequencies are not finite')
    hit = _unresolved_mode(s.cfg, s.modes)
    if hit:
        raise s.blame(('integrator.time_step',) + hit[1], hit[0])


def _rule_trial(s: _Subject) -> Steps[None]:
    """Rule 4: trial (equilibrium finite and in range, a short ramp integrates)."""
    from .stepping import SimulationError, Stepper
    yield
    try:
        sim = Stepper(s.model, theta1=0.0)
        yield
        u0 = sim.state.theta
        if not (np.all(np.isfinite(u0)) and np.all(np.abs(u0) <= ANGLE_LIMIT)):
            raise s.blame(('load.output_torque',), f'the static equilibrium '
                          f'(theta2, theta3, theta4) = {u0} is not finite or beyond '
                          f'{ANGLE_LIMIT:g} rad')
        sim.advance_to(0.5 * TRIAL_TIME, TRIAL_ANGLE)
        yield
        sim.advance_to(TRIAL_TIME, TRIAL_ANGLE)
        state = sim.state
        if not (np.all(np.isfinite(state.theta)) and np.all(np.isfinite(state.omega))):
            raise SimulationError('non-finite state')
    except SimulationError as exc:
        raise _trial_failure(s.cfg, s.changed, s.modes, str(exc)) from None


#: the rules of the module doc, in order; each a check in steps on the set
_RULES: tuple[Callable[[_Subject], Steps[None]], ...] = (
    _rule_tooth_stiffness, _rule_spring_chain, _rule_modes, _rule_trial)


def _unresolved_mode(cfg: Parameters, m: tuple[np.ndarray, np.ndarray]
                     ) -> tuple[str, tuple[str, ...]] | None:
    """(text, inertia keys) when the highest mode is beyond the step's Nyquist limit; ``m``:
    the natural frequencies [Hz] and shapes (:func:`~.modal.natural_modes`)."""
    dt = cfg.integrator.time_step
    hz, shapes = m
    i = int(np.argmax(hz))
    wdt = 2.0 * math.pi * float(hz[i]) * dt
    if wdt <= OMEGA_DT_MAX:
        return None
    body = int(np.argmax(np.abs(shapes[:, i])))
    names = ('worm', 'gear', 'antenna')
    return (f'the highest mode ({hz[i]:.4g} Hz, mostly the {names[body]}) is not '
            f'resolved by integrator.time_step = {dt:g} s (omega dt = {wdt:.3g} > pi); reduce '
            f'the time step below {OMEGA_DT_MAX / (2 * math.pi * hz[i]):.3g} s or '
            f'check the {names[body]} inertia', _INERTIA[body])


def _trial_failure(cfg: Parameters, changed: Sequence[str], m: tuple[np.ndarray, np.ndarray],
                   what: str) -> ConfigError:
    """The trial move failed: name the unresolved mode if there is one (the usual cause:
    a tiny inertia or a huge stiffness puts a mode far above the step's Nyquist limit, where
    the implicit step exists but Newton cannot follow the nonlinear mesh), else the keys."""
    why = f'a {TRIAL_TIME * 1e3:g} ms trial move of {TRIAL_ANGLE:g} rad fails ({what})'
    hit = _unresolved_mode(cfg, m)
    if hit:
        return _blame(cfg, changed, ('integrator.time_step',) + hit[1], f'{why}: {hit[0]}')
    return _blame(cfg, changed, (), why)


def diagnose(cfg: Parameters) -> str:
    """Text for the message of :class:`~worm_gear_sim.dynamics.simulation.SimulationError` with a
    usable ``cfg``: 'likely cause: ...' naming the parameters when a known cause applies (a
    mode beyond the step's Nyquist limit, a friction regularisation below 1e-8 m/s), else
    'no known cause; ...' with the keys that differ from the defaults ('' if none)."""
    try:
        with np.errstate(all='ignore'):
            from .modal import natural_modes
            hit = _unresolved_mode(cfg, natural_modes(cfg))
    except Exception:  # noqa: BLE001 - a hint only
        hit = None
    parts = [hit[0] + f' ({", ".join(hit[1])})'] if hit else []
    fr, integ = cfg.friction, cfg.integrator
    # measured on the paper's move at dt = 10 us: runs at v_eps = 1e-8 m/s, stops at 3e-9
    if fr.model != 'off' and fr.regularization_velocity < 1e-8:
        parts.append(f'friction.regularization_velocity = {fr.regularization_velocity:g} m/s '
                     'makes the friction law a near step that Newton cannot follow '
                     f'even at dt / 2^{integ.max_subdivision_level}; 1e-4 m/s is the default')
    if parts:
        return 'likely cause: ' + '; '.join(parts)
    changed = _differs_from_defaults(cfg)
    if changed:
        flat = cfg.to_flat_dict()
        return ('no known cause; parameters that differ from the defaults: '
                + ', '.join(f'{k} = {flat[k]!r}' for k in changed[:6])
                + (' ...' if len(changed) > 6 else ''))
    return ''
