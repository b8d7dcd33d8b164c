"""The :class:`ContactModel` base class and the particle-wall impact it integrates."""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pygran_core import params
from pygran_core.errors import ConfigError, UnsupportedFeature, unknown_key
from pygran_core.simulation.models import mixing

__all__ = ["ROLLING_MODELS", "ContactModel", "Impact"]

Array = NDArray[np.float64]

#: The rolling-resistance models of LIGGGHTS 3.8 (``rolling_friction <name>``) that a contact
#: model names with ``rolling=``; ``cdt``, the original PyGran's, is the default.
#: With ``k_n``/``k_t`` the normal/tangential stiffness and ``mu_r`` the
#: ``coefficientRollingFriction``, the spring models limit their torque to ``mu_r R* |F_n|``.
ROLLING_MODELS: Mapping[str, str] = MappingProxyType(
    {
        "cdt": "constant directional torque mu_r R* |F_n| against the relative rotation",
        "epsd": "elastic-plastic spring-dashpot (Ai et al. 2011), k_r = 2.25 k_n mu_r^2 R*^2, "
        "damped by coefficientRollingViscousDamping",
        "epsd2": "elastic-plastic spring (Iwashita & Oda 1998), k_r = k_t R*^2, no damping",
        "epsd3": "epsd with a user prefactor, k_r = coeffRollingStiffness k_n mu_r^2 R*^2",
    }
)


#: The methods that define a model's force law (see :attr:`ContactModel.kernel`); ``__init__``
#: because it may change the coefficients, which engines compute from the materials themselves.
FORCE_LAW = (
    "__init__",
    "normal_force",
    "tangential_force",
    "rolling_torque",
    "_model_coefficients",
    "_tangential_coefficients",
    "_in_contact",
    "_separation_overlap",
)


@dataclass(frozen=True)
class Impact:
    """A particle-wall impact, unpacked as ``time, soln, force = model.displacement()``.

    ``soln[:, 0]`` is the normal overlap and ``soln[:, 1]`` its rate (positive while
    approaching), from first touch (``soln[0] = (0, v)``) to the end of contact: the
    separation point, or for a captured particle the point where it turns back towards
    the wall for the second time. ``force`` is the normal force on the particle (positive
    repulsive) at each time.
    """

    time: Array
    soln: Array
    force: Array
    captured: bool

    def __iter__(self) -> Iterator[Array]:
        return iter((self.time, self.soln, self.force))

    @property
    def restitution(self) -> float:
        """Normal coefficient of restitution ``|v_out / v_in|``; 0 for a captured particle."""
        return 0.0 if self.captured else abs(float(self.soln[-1, 1] / self.soln[0, 1]))

    @property
    def contact_time(self) -> float:
        """Duration of the contact; ``inf`` for a captured particle."""
        return math.inf if self.captured else float(self.time[-1] - self.time[0])

    @property
    def max_overlap(self) -> float:
        return float(self.soln[:, 0].max())

    @property
    def max_force(self) -> float:
        return float(self.force.max())


class _Event:
    """A terminal event of ``scipy.integrate.solve_ivp``: ``value(t, y, history)`` crossing
    zero in ``direction`` (-1 falling, 1 rising) ends the integration."""

    terminal = True

    def __init__(self, value: Callable[[float, Array, float | None], float], direction: int) -> None:
        self.value, self.direction = value, direction

    def __call__(self, t: float, y: Array, history: float | None) -> float:
        return self.value(t, y, history)


class ContactModel(abc.ABC):
    """Base class of the contact models: a normal force law plus friction and rolling resistance.

    ``Model(material=dict)`` takes a material with the keys of :mod:`pygran_core.params`
    plus ``radius`` and optionally ``mass`` (else computed from ``density``). By default
    the contact is particle-wall: a flat wall (infinite radius and mass) of the same
    material. ``partner`` gives the other body's material instead, with its own
    ``radius``/``mass`` for a sphere-sphere contact (omit them for a wall); properties
    missing from it are taken from ``material``. Pair values come from
    :mod:`~pygran_core.simulation.models.mixing`.

    Sign conventions: the overlap ``delta > 0`` in contact, its rate positive while the
    bodies approach; normal forces are positive when repulsive. Tangential vectors lie on
    the last array axis. ``max_overlap`` is the normal history (largest overlap of the
    contact so far) for models with hysteresis; ``None`` means the contact is loading.

    ``limitForce=True`` (the original PyGran's option) keeps the normal force from
    turning attractive at the end of a contact; see each model for what that means there.
    ``rolling`` names the rolling-resistance model engines use, one of
    :data:`ROLLING_MODELS` (LIGGGHTS' ``rolling_friction`` styles); the class attribute
    holds the default ``"cdt"``, so an engine given the class or an instance reads
    ``model.rolling`` either way.
    """

    #: The force law engines run for this model: the engine capability that names their
    #: kernel (``"spring-dashpot"``, ``"hertz-mindlin"``, ``"thornton-ning"``), or ``None``
    #: when no engine has one. Inherited: a subclass that adds methods or sets options runs
    #: on every engine with its parent's kernel. A subclass that overrides a method of
    #: :data:`FORCE_LAW` has no kernel unless it declares one (an engine plugin that runs
    #: its law declares the same capability), so no engine runs the parent's law instead.
    kernel: ClassVar[str | None] = None
    #: The method whose override took the parent's kernel away (for the engines' refusal).
    kernel_lost_by: ClassVar[str | None] = None
    #: Material keys a model cannot do without (``density`` or ``mass`` is always needed).
    required: ClassVar[tuple[str, ...]] = ("youngsModulus", "poissonsRatio", "radius")
    #: The rolling-resistance model, a key of :data:`ROLLING_MODELS`.
    rolling: str = "cdt"
    #: Whether the normal force is kept from turning attractive (``limitForce``).
    limit_force: bool = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        overridden = [name for name in FORCE_LAW if name in vars(cls)]
        if "kernel" not in vars(cls) and overridden:
            cls.kernel = None
            cls.kernel_lost_by = f"{cls.__name__}.{overridden[0]}"

    @classmethod
    def configure(cls, *, rolling: str | None = None, limitForce: bool | None = None) -> type[ContactModel]:
        """This model with other defaults, for ``DEM(model=...)``: e.g.
        ``HertzMindlin.configure(rolling='epsd2')``. The subclass is named after its options
        (``HertzMindlin[rolling=epsd2]``), so an engine without them refuses it by name."""
        rolling = cls.rolling if rolling is None else _checked_rolling(rolling)
        limit_force = cls.limit_force if limitForce is None else _checked_limit_force(limitForce)
        if (rolling, limit_force) == (cls.rolling, cls.limit_force):
            return cls
        options = [f"rolling={rolling}"] * (rolling != "cdt") + ["limitForce=True"] * limit_force
        name = f"{cls.__name__}[{','.join(options)}]" if options else cls.__name__
        attributes = {"rolling": rolling, "limit_force": limit_force, "__doc__": cls.__doc__}
        return type(name, (cls,), {**attributes, "__module__": cls.__module__})

    def __init__(
        self,
        material: Mapping[str, float],
        *,
        partner: Mapping[str, float] | None = None,
        limitForce: bool | None = None,
        rolling: str | None = None,
    ) -> None:
        if limitForce is not None:
            self.limit_force = _checked_limit_force(limitForce)
        if rolling is not None:
            self.rolling = _checked_rolling(rolling)
        mine = params.validate(material, allow=("radius", "mass"))
        theirs = {} if partner is None else params.validate(partner, allow=("radius", "mass"))
        missing = [key for key in self.required if key not in mine]
        if "mass" not in mine and "density" not in mine:
            missing.append("density")
        if missing:
            raise ConfigError(f"{type(self).__name__} needs the material key(s) {', '.join(missing)}.")
        self.material: Mapping[str, float] = MappingProxyType(mine)
        for key, value in mine.items():
            if key not in ("radius", "mass"):
                theirs.setdefault(key, value)
        self.radius = mine["radius"]
        self.mass = _sphere_mass(mine)
        other_mass = theirs.get("mass", _sphere_mass(theirs)) if "radius" in theirs else math.inf
        self.effective_radius = float(mixing.effective_radius(self.radius, theirs.get("radius", math.inf)))
        self.effective_mass = float(mixing.effective_mass(self.mass, other_mass))
        moduli = (
            mine["youngsModulus"],
            mine["poissonsRatio"],
            theirs["youngsModulus"],
            theirs["poissonsRatio"],
        )
        self.effective_modulus = float(mixing.effective_modulus(*moduli))
        self.effective_shear_modulus = float(mixing.effective_shear_modulus(*moduli))

        def pair(key: str, rule: Callable[[float, float], mixing.Real]) -> float | None:
            return float(rule(mine[key], theirs[key])) if key in mine else None

        self.friction = pair("coefficientFriction", mixing.pair_friction)
        self.rolling_friction = pair("coefficientRollingFriction", mixing.pair_friction)
        self.restitution_coefficient = pair("coefficientRestitution", mixing.pair_restitution)
        self.cohesion = pair("cohesionEnergyDensity", mixing.pair_cohesion) or 0.0
        self.yield_pressure = pair("yieldPress", mixing.pair_yield_pressure)

    @property
    def coefficients(self) -> Mapping[str, float]:
        """The pair coefficients of this contact (read-only)."""
        names = (
            "effective_radius",
            "effective_mass",
            "effective_modulus",
            "effective_shear_modulus",
            "friction",
            "rolling_friction",
            "restitution_coefficient",
            "cohesion",
            "yield_pressure",
        )
        values = {name: getattr(self, name) for name in names} | self._model_coefficients()
        return MappingProxyType({k: v for k, v in values.items() if v is not None})

    def _model_coefficients(self) -> dict[str, float]:
        """Model-specific constant coefficients (stiffness, damping...)."""
        return {}

    # --- force laws -------------------------------------------------------------------
    @abc.abstractmethod
    def normal_force(
        self, overlap: ArrayLike, overlap_rate: ArrayLike, max_overlap: ArrayLike | None = None
    ) -> Array:
        """Normal force (positive repulsive) at the given overlap and overlap rate."""

    @abc.abstractmethod
    def _tangential_coefficients(self, overlap: Array, max_overlap: ArrayLike | None) -> tuple[Array, Array]:
        """Tangential stiffness ``k_t`` and damping ``gamma_t`` at the given overlap."""

    def _in_contact(self, overlap: Array, max_overlap: ArrayLike | None) -> NDArray[np.bool_]:
        return overlap > 0

    def _separation_overlap(self, max_overlap: float) -> float:
        """Overlap at which an unloading contact with this history breaks."""
        return 0.0

    def tangential_force(
        self,
        overlap: ArrayLike,
        tangential_overlap: ArrayLike,
        tangential_rate: ArrayLike,
        normal_force: ArrayLike,
        max_overlap: ArrayLike | None = None,
    ) -> tuple[Array, Array]:
        """Tangential force with history and Coulomb limit; returns ``(force, tangential_overlap)``.

        ``F_t = -k_t xi - gamma_t v_t``, with ``xi`` the accumulated tangential
        displacement (the history the engine integrates, shape ``(..., d)``) and ``v_t`` the
        tangential relative velocity. When the spring alone exceeds Coulomb's limit,
        ``|k_t xi| > mu |F_n|``, the contact slides: the force is the spring scaled to
        ``mu |F_n|``, without dashpot, and the history is set to match, ``xi <- -F_t / k_t``
        (LIGGGHTS ``tangential_model_history.h``). Out of contact both are zero.
        """
        if self.friction is None:
            raise ConfigError(f"{type(self).__name__}: the tangential force needs 'coefficientFriction'.")
        overlap = np.asarray(overlap, float)
        xi = np.asarray(tangential_overlap, float)
        rate = np.asarray(tangential_rate, float)
        kt, gammat = (c[..., None] for c in self._tangential_coefficients(overlap, max_overlap))
        contact = self._in_contact(overlap, max_overlap)[..., None]
        spring = -kt * xi
        magnitude = np.linalg.norm(spring, axis=-1, keepdims=True)
        limit = self.friction * np.abs(np.asarray(normal_force, float))[..., None]
        slip = magnitude > limit
        ratio = np.where(slip, limit / np.where(slip, magnitude, 1.0), 1.0)
        force = np.where(slip, ratio * spring, spring - gammat * rate)
        history = np.where(slip, ratio * xi, xi)
        return np.where(contact, force, 0.0), np.where(contact, history, 0.0)

    def rolling_torque(self, normal_force: ArrayLike, angular_velocity: ArrayLike) -> Array:
        """Rolling resistance torque on body 1, LIGGGHTS ``rolling_friction cdt``.

        ``M_r = -mu_r R* |F_n| w / |w|`` with ``w = omega_1 - omega_2`` the relative angular
        velocity (shape ``(..., 3)``); zero where ``w = 0``. Body 2 gets ``-M_r``. LIGGGHTS
        (``rolling_model_cdt.h``) and the native engine take for ``F_n`` the normal force's
        elastic part ``k_n delta``, without damping and cohesion: pass that to match them.
        The spring models (``epsd``...) carry a torque history only engines integrate:
        for them this raises :class:`~pygran_core.errors.UnsupportedFeature`.
        """
        if self.rolling != "cdt":
            raise UnsupportedFeature(
                f"{type(self).__name__}.rolling_torque is the cdt law; rolling={self.rolling!r} is "
                "computed by the engines (its torque has a history). Use rolling='cdt' here."
            )
        if self.rolling_friction is None:
            raise ConfigError(
                f"{type(self).__name__}: the rolling torque needs 'coefficientRollingFriction'."
            )
        w = np.asarray(angular_velocity, float)
        norm = np.linalg.norm(w, axis=-1, keepdims=True)
        direction = np.divide(w, norm, out=np.zeros_like(w), where=norm > 0)
        moment = self.rolling_friction * self.effective_radius * np.abs(np.asarray(normal_force, float))
        return -moment[..., None] * direction

    # --- impacts ----------------------------------------------------------------------
    @abc.abstractmethod
    def contactTime(self, velocity: float | None = None) -> float:
        """Duration of a particle-wall impact at ``velocity`` (default ``characteristicVelocity``)."""

    def _velocity(self, velocity: float | None) -> float:
        if velocity is None:
            if "characteristicVelocity" not in self.material:
                raise ConfigError(
                    f"{type(self).__name__}: give an impact velocity or 'characteristicVelocity'."
                )
            return self.material["characteristicVelocity"]
        if not velocity > 0:
            raise ConfigError(f"The impact velocity must be > 0, got {velocity!r}.")
        return float(velocity)

    def displacement(self, velocity: float | None = None, samples: int = 400) -> Impact:
        """Integrate a normal impact at ``velocity`` (default ``characteristicVelocity``).

        Solves ``m* d2delta/dt2 = -F_n(delta, ddelta/dt)`` from ``delta = 0``,
        ``ddelta/dt = v`` with ``scipy.integrate.solve_ivp`` in two phases, each ended by an
        event: loading until the overlap rate vanishes, then unloading (with that maximum
        overlap as history) until the contact breaks, or until the overlap rate vanishes
        again (the particle is captured). Each phase is sampled at ``samples`` times.
        Unpack the result as ``time, soln, force``; see :class:`Impact`.
        """
        v0 = self._velocity(velocity)
        span = 50 * self.contactTime(v0)
        options = {
            "method": "DOP853",
            "rtol": 1e-10,
            "atol": 1e-13 * np.array([v0 * span, v0]),
            "dense_output": True,
        }

        from scipy.integrate import solve_ivp  # here: importing PyGran need not load scipy.integrate

        def rhs(t: float, y: Array, history: float | None) -> tuple[float, float]:
            return y[1], -float(self.normal_force(y[0], y[1], history)) / self.effective_mass

        turning = _Event(lambda t, y, history: y[1], direction=-1)
        returning = _Event(lambda t, y, history: y[1], direction=1)
        separating = _Event(lambda t, y, history: y[0] - separation, direction=-1)

        loading = solve_ivp(rhs, (0.0, span), (0.0, v0), events=turning, args=(None,), **options)
        if loading.status != 1:
            raise RuntimeError(f"{type(self).__name__}: the impact did not turn back within {span:g} s.")
        t1, y1 = loading.t_events[0][0], loading.y_events[0][0]
        history = float(y1[0])
        separation = self._separation_overlap(history)
        unloading = solve_ivp(
            rhs, (t1, t1 + span), y1, events=[separating, returning], args=(history,), **options
        )
        if unloading.status != 1:
            raise RuntimeError(f"{type(self).__name__}: the contact neither broke nor captured the particle.")
        captured = unloading.t_events[1].size > 0
        t2 = (unloading.t_events[1] if captured else unloading.t_events[0])[0]

        times = (np.linspace(0.0, t1, samples), np.linspace(t1, t2, samples)[1:])
        states = [loading.sol(times[0]).T, unloading.sol(times[1]).T]
        forces = [
            self.normal_force(states[0][:, 0], states[0][:, 1]),
            self.normal_force(states[1][:, 0], states[1][:, 1], history),
        ]
        return Impact(np.concatenate(times), np.concatenate(states), np.concatenate(forces), captured)

    def restitution(self, velocity: float | None = None) -> float:
        """Coefficient of restitution realised by a particle-wall impact at ``velocity``."""
        return self.displacement(velocity).restitution

    def __repr__(self) -> str:
        rolling = "" if self.rolling == "cdt" else f", rolling={self.rolling!r}"
        return f"{type(self).__name__}(material={dict(self.material)!r}{rolling})"


def _sphere_mass(material: Mapping[str, float]) -> float:
    if "mass" in material:
        return material["mass"]
    if "density" not in material:
        raise ConfigError("A sphere needs 'density' or 'mass'.")
    return 4.0 / 3.0 * math.pi * material["radius"] ** 3 * material["density"]


def _checked_rolling(rolling: object) -> str:
    if not isinstance(rolling, str) or rolling not in ROLLING_MODELS:
        raise unknown_key("rolling-friction model (rolling=)", str(rolling), ROLLING_MODELS)
    return rolling


def _checked_limit_force(limit_force: object) -> bool:
    if not isinstance(limit_force, (bool, np.bool_)):
        raise ConfigError(f"limitForce must be True or False, got {limit_force!r}")
    return bool(limit_force)
