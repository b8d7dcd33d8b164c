"""The native solver's contact models: their settings checked and mixed into the per-pair tables
the compiled core takes."""

from __future__ import annotations

import math

import numpy as np

from pygran_core.errors import ConfigError
from pygran_core.simulation.models import mixing
from pygran_native.arguments import array_of

#: The contact models, as the compiled core numbers them, and their history values per contact.
MODELS = {"hooke": 0, "hertz": 1, "thornton-ning": 2}
HISTORY = {"hooke": 4, "hertz": 4, "thornton-ning": 7}
#: Rolling resistance models (LIGGGHTS ``rolling_friction``); those after cdt keep a spring
#: torque: 3 more history values per contact.
ROLLING = {"cdt": 0, "epsd": 1, "epsd2": 2}
#: The contact-model settings a checkpoint stores (the arguments of Solver.set_contact_model).
MODEL_KEYS = (
    "youngs",
    "poisson",
    "restitution",
    "friction",
    "rolling_friction",
    "rolling_damping",
    "limit_force",
    "cohesion_energy",
    "yield_pressure",
    "characteristic_velocity",
)


def model_tables(
    kind: str,
    *,
    rolling,
    limit_force,
    restitution,
    yield_pressure,
    characteristic_velocity,
    **per_type_values,
):
    """The arguments of ``Core.set_model`` for a contact model, and the settings as given
    (see :meth:`Solver.set_contact_model`); a ConfigError naming a bad one."""
    if kind not in MODELS:
        raise ConfigError(f"kind: unknown contact model {kind!r}; choose one of {', '.join(MODELS)}.")
    if rolling not in ROLLING:
        raise ConfigError(f"rolling: unknown rolling model {rolling!r}; choose one of {', '.join(ROLLING)}.")
    if limit_force not in (0, 1):  # True, False, or 1.0, 0.0 from a checkpoint
        raise ConfigError(f"limit_force: must be True or False, got {limit_force!r}.")
    E = array_of(np.atleast_1d(per_type_values["youngs"]), "youngs", (-1,))
    nt = E.shape[0]
    if nt == 0:
        raise ConfigError("youngs: give at least one type.")

    def per_type(value, name, check):
        """One value per type, a copy (the settings keep it)."""
        arr = array_of(
            np.broadcast_to(np.asarray(value, float), (nt,)) if np.ndim(value) == 0 else value,
            name,
            (nt,),
        ).copy()
        if not np.all(check(arr)):
            raise ConfigError(f"{name}: out of range: {arr.tolist()}.")
        return arr

    def pairwise(value, name, check, rule):
        """The (nt, nt) pair matrix ``value`` as given (symmetric), or mixed by ``rule`` from
        per-type values."""
        if np.ndim(value) < 2:
            return mixing.pair_table(rule, per_type(value, name, check))
        arr = array_of(value, name, (nt, nt)).copy()
        if not np.all(check(arr)) or not np.array_equal(arr, arr.T):
            raise ConfigError(f"{name}: a pair matrix must be symmetric and in range: {arr.tolist()}.")
        return arr

    E = per_type(E, "youngs", lambda a: a > 0)
    nu = per_type(per_type_values["poisson"], "poisson", lambda a: (a > -1) & (a < 0.5))

    def non_negative(name, rule):
        return pairwise(per_type_values[name], name, lambda a: a >= 0, rule)

    mu = non_negative("friction", mixing.pair_friction)
    mur = non_negative("rolling_friction", mixing.pair_friction)
    coh = non_negative("cohesion_energy", mixing.pair_cohesion)
    eta = non_negative("rolling_damping", mixing.pair_friction)  # the smaller one, as LIGGGHTS mixes it
    vchar = 0.0
    if kind == "thornton-ning":
        if yield_pressure is None:
            raise ConfigError("yield_pressure: required by the thornton-ning model.")
        py = per_type(yield_pressure, "yield_pressure", lambda a: a > 0)
        damp = np.zeros((nt, nt))
    else:
        if restitution is None:
            raise ConfigError(f"restitution: required by the {kind} model.")
        e = pairwise(restitution, "restitution", lambda a: (a > 0) & (a <= 1), mixing.pair_restitution)
        py = np.zeros(nt)
        # LIGGGHTS' beta is -zeta
        zeta = np.asarray(mixing.damping_ratio(e), float)
        damp = (2 * math.sqrt(5 / 6) if kind == "hertz" else 2.0) * zeta
        if kind == "hooke":
            if characteristic_velocity is None or not characteristic_velocity > 0:
                raise ConfigError("characteristic_velocity: the hooke model needs a value > 0.")
            vchar = float(characteristic_velocity)
    tables = [
        mixing.pair_table(mixing.effective_modulus, E, nu),
        mixing.pair_table(mixing.effective_shear_modulus, E, nu),
        mu,
        mur,
        np.asarray(damp, float) + np.zeros((nt, nt)),
        coh,
        mixing.pair_table(mixing.pair_yield_pressure, py) if kind == "thornton-ning" else np.zeros((nt, nt)),
        eta,
    ]
    model = {
        "kind": kind,
        "youngs": E,
        "poisson": nu,
        "restitution": restitution,
        "friction": mu,
        "rolling": rolling,
        "rolling_friction": mur,
        "rolling_damping": eta,
        "limit_force": bool(limit_force),
        "cohesion_energy": coh,
        "yield_pressure": yield_pressure,
        "characteristic_velocity": characteristic_velocity,
    }
    history = HISTORY[kind] + (3 if rolling != "cdt" else 0)
    args = (
        MODELS[kind],
        history,
        ROLLING[rolling],
        bool(limit_force),
        *(np.ascontiguousarray(t) for t in tables),
        vchar,
    )
    return args, model
