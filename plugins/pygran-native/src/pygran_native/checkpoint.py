"""The native solver's checkpoints: its state as numpy arrays, and every entry of one checked
before it is restored (see :class:`pygran_native.solver.Solver`)."""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from pygran_core.errors import ConfigError, ReadError
from pygran_core.simulation.checkpoint import decode_text, encode_text
from pygran_native._solver import HARMONICS, LOST_PLACES, MOTION_VALUES, SLOT_VALUES, VIBRATION_VALUES
from pygran_native.base import SolverBase
from pygran_native.contact_model import MODEL_KEYS, MODELS, ROLLING, model_tables
from pygran_native.walls import SLOT, VIBRATION, WALL_KINDS


class Checkpoints(SolverBase):
    """A solver's state for a checkpoint, and its restoring: a part of
    :class:`~pygran_native.solver.Solver`."""

    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue bitwise identically, as a dict of numpy arrays.

        Numeric arrays only (strings are UTF-8 bytes), so it can be stored in HDF5 as is.
        """
        if self._model is None:
            raise ConfigError("get_state: no contact model set yet.")
        state = {f"core_{k}": v for k, v in self._core.get_state().items()}
        model = self._model
        state["model_kind"] = encode_text(model["kind"])
        state["model_rolling"] = encode_text(model["rolling"])
        for key in MODEL_KEYS:
            state[f"model_{key}"] = np.array(np.nan if model[key] is None else model[key], float)
        state["viscous"] = self._viscous.copy()
        state["counters"] = np.array([self._next_id, self._next_wall, self._next_vertex], np.int64)
        if self._next_body:
            state["clump_counter"] = np.array([self._next_body], np.int64)
        state["wall_handles"] = np.array(list(self._walls), np.int64)
        state["wall_kinds"] = np.array([WALL_KINDS.index(k) for k in self._walls.values()], np.int64)
        state["rng"] = encode_text(json.dumps(self.rng.bit_generator.state))
        return state

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore a :meth:`get_state` result (box, periodicity and threads are this solver's).

        Every entry is checked, against the particle count, the others and the solver's layout,
        before anything is changed: a malformed state is a :class:`ReadError` naming the entry
        and what it should hold, and leaves the solver as it was.
        """
        try:
            checked = checked_state(state, self.periodic)
        except ReadError:
            raise
        except (KeyError, IndexError, ValueError, TypeError, AttributeError, OverflowError) as exc:
            # a JSON or UTF-8 decoding error is a ValueError
            raise ReadError(f"checkpoint state: malformed ({type(exc).__name__}: {exc})") from None
        tables, model, viscous, core, counters, walls, rng = checked
        self._core.set_model(*tables)
        self._model = model
        self._viscous = viscous
        self._core.set_viscous(viscous)
        self._core.set_state(core)
        self._next_id, self._next_wall, self._next_vertex, self._next_body = counters
        self._walls = walls
        self.rng.bit_generator.state = rng


_IMAGES = 27  #: periodic image codes 9 (sx + 1) + 3 (sy + 1) + (sz + 1) of the neighbour list
_FLAGS = 0x80 | 0x40  #: the other bits of a neighbour-list code (TOUCH, WRAP; see _solver.pyx)


def _fail(key: str, expected: str, found: object = None) -> ReadError:
    got = "" if found is None else f", found {found}"
    return ReadError(f"checkpoint state entry {key!r}: expected {expected}{got}.")


def _entry(
    state: Mapping[str, np.ndarray], key: str, dtype, length: int | None = None, basis: str = ""
) -> np.ndarray:
    """``state[key]`` as a flat array of exactly ``dtype`` (and ``length``, which ``basis``
    explains), or a ReadError."""
    if key not in state:
        raise ReadError(f"checkpoint state: missing entry {key!r}.")
    value = np.asarray(state[key])
    dtype = np.dtype(dtype)
    if value.dtype != dtype:
        raise _fail(key, f"{dtype} values", value.dtype)
    if value.ndim != 1:
        raise _fail(key, "a one-dimensional array", f"shape {value.shape}")
    if length is not None and value.shape[0] != length:
        raise _fail(key, f"{length} values{basis}", value.shape[0])
    return np.ascontiguousarray(value)


def _text(state: Mapping[str, np.ndarray], key: str) -> str:
    """``state[key]``, UTF-8 text stored as bytes, or a ReadError."""
    try:
        return decode_text(_entry(state, key, np.uint8))
    except UnicodeDecodeError as exc:
        raise _fail(key, "UTF-8 text", f"bytes that are not: {exc}") from None


def _within(key: str, values: np.ndarray, lo: float, hi: float, what: str = "") -> None:
    """Every value finite and in [lo, hi), or a ReadError."""
    ok = np.isfinite(values) & (values >= lo) & (values < hi) if values.size else np.ones(0, bool)
    if not np.all(ok):
        bad = values[~ok][0]
        raise _fail(key, what or f"values in [{lo:g}, {hi:g})", f"{bad!r}")


def _offsets(key: str, start: np.ndarray, total: int, listed: str) -> None:
    """CSR offsets: from 0, non-decreasing, ending at ``total`` (the length of ``listed``)."""
    if start[0] != 0 or np.any(np.diff(start) < 0) or start[-1] != total:
        raise _fail(
            key,
            f"offsets from 0, non-decreasing, up to the length {total} of {listed}",
            f"{start[0]}..{start[-1]}" + (" (decreasing somewhere)" if np.any(np.diff(start) < 0) else ""),
        )


def checked_state(state: Mapping[str, np.ndarray], periodic: tuple[bool, ...]):
    """What :meth:`Solver.set_state` applies, each entry checked (see there)."""
    kind = _text(state, "model_kind")
    if kind not in MODELS:
        raise _fail("model_kind", f"one of {', '.join(MODELS)}", repr(kind))
    settings = {}
    for key in MODEL_KEYS:
        value = np.asarray(state[f"model_{key}"]) if f"model_{key}" in state else None
        if value is None or value.dtype != np.float64 or value.ndim > 2:
            raise _fail(
                f"model_{key}",
                "a float64 number, one per type or a pair matrix",
                None if value is None else value.dtype,
            )
        settings[key] = (
            None if value.ndim == 0 and np.isnan(value) else (float(value) if value.ndim == 0 else value)
        )
    rolling = _text(state, "model_rolling")
    if rolling not in ROLLING:
        raise _fail("model_rolling", f"one of {', '.join(ROLLING)}", repr(rolling))
    try:
        tables, model = model_tables(kind, rolling=rolling, **settings)
    except ConfigError as exc:  # "poisson: expected ..."
        name, _, problem = str(exc).partition(": ")
        youngs = settings["youngs"]
        types = 0 if youngs is None else np.size(youngs)
        raise ReadError(
            f"checkpoint state entry 'model_{name}': {problem} (model_youngs gives {types} types)"
        ) from None
    nt, hs = model["youngs"].shape[0], tables[1]
    viscous = _entry(state, "viscous", float, nt, " (one per type of model_youngs)")
    _within("viscous", viscous, 0, np.inf, "damping coefficients >= 0")

    def get(key, dtype, length=None, basis=""):
        return _entry(state, f"core_{key}", dtype, length, basis and f" ({basis})")

    out = {}
    r = out["r"] = get("r", float)
    n = r.shape[0]
    for key in ("x", "v", "w", "f", "t", "x0"):
        out[key] = get(key, float, 3 * n, "3 per particle of core_r")
    out["m"] = get("m", float, n, "one per particle of core_r")
    _within("core_r", r, 0, np.inf, "radii > 0")
    _within("core_m", out["m"], 0, np.inf, "masses > 0")
    for key in ("r", "m"):
        if np.any(out[key] == 0):
            raise _fail(f"core_{key}", "values > 0", 0.0)
    out["type"] = get("type", np.int32, n, "one per particle of core_r")
    _within("core_type", out["type"], 0, nt, f"types in [0, {nt - 1}]")
    ids = out["id"] = get("id", np.int64, n, "one per particle of core_r")
    _within("core_id", ids, 0, np.inf, "ids >= 0")
    if len(np.unique(ids)) != n:
        raise _fail("core_id", "distinct ids", "repeated ids")
    # neighbour list: rows in storage order, partners j > i (a half list), image codes
    nb_start = out["nb_start"] = get("nb_start", np.int32, n + 1, "one more than the particles of core_r")
    nb_j = out["nb_j"] = get("nb_j", np.int32)
    npair = nb_j.shape[0]
    _offsets("core_nb_start", nb_start, npair, "core_nb_j")
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(nb_start))
    if np.any(nb_j >= n) or np.any(nb_j <= rows):
        raise _fail("core_nb_j", f"partners j of row i with i < j < {n}", "others")
    nb_s = out["nb_s"] = get("nb_s", np.uint8, npair, "one per pair of core_nb_j")
    image = nb_s & ~np.uint8(_FLAGS)
    shifts = np.stack([image // 9, image // 3 % 3, image % 3], axis=1) if npair else np.ones((0, 3), int)
    if np.any(image >= _IMAGES) or np.any((shifts != 1) & ~np.array(periodic)):
        raise _fail("core_nb_s", "periodic image codes 0..26 across periodic axes only", "others")
    out["nb_h"] = get("nb_h", float, npair * hs, f"{hs} per pair of core_nb_j")
    # wall elements and the wall list
    ekind = out["ekind"] = get("ekind", np.int32)
    ne = ekind.shape[0]
    _within("core_ekind", ekind, 0, 3, "element kinds 0 (plane), 1 (cylinder), 2 (triangle)")
    out["etype"] = get("etype", np.int32, ne, "one per element of core_ekind")
    _within("core_etype", out["etype"], 0, nt, f"types in [0, {nt - 1}]")
    out["ewall"] = get("ewall", np.int32, ne, "one per element of core_ekind")
    out["evid"] = get("evid", np.int32, 3 * ne, "3 per element of core_ekind")
    _within("core_evid", out["evid"], -1, np.inf, "vertex ids >= -1")
    out["emoving"] = get("emoving", np.int32, ne, "one per element of core_ekind")
    _within("core_emoving", out["emoving"], 0, 2, "flags 0 or 1")
    for key in ("egeo", "eref", "ebuilt"):
        out[key] = get(key, float, 9 * ne, "9 per element of core_ekind")
        _within(f"core_{key}", out[key], -np.inf, np.inf, "finite coordinates")
    out["emot"] = get("emot", float, MOTION_VALUES * ne, f"{MOTION_VALUES} per element of core_ekind")
    _within("core_emot", out["emot"], -np.inf, np.inf, "finite motion values")
    geo = out["egeo"].reshape(ne, 9)
    cylinders = geo[ekind == 1]
    if np.any(~np.isin(cylinders[:, 0], (0.0, 1.0, 2.0))) or np.any(cylinders[:, 3] <= 0):
        raise _fail("core_egeo", "cylinders with an axis 0, 1 or 2 and a radius > 0", "others")
    wl_start = out["wl_start"] = get("wl_start", np.int32, n + 1, "one more than the particles of core_r")
    wl_e = out["wl_e"] = get("wl_e", np.int32)
    nwall = wl_e.shape[0]
    _offsets("core_wl_start", wl_start, nwall, "core_wl_e")
    _within("core_wl_e", wl_e, 0, ne, f"wall elements in [0, {ne - 1}]")
    wl_h = out["wl_h"] = get("wl_h", float, nwall * (hs + 1), f"{hs + 1} per entry of core_wl_e")
    if nwall and not np.all(np.isin(wl_h.reshape(nwall, hs + 1)[:, hs], (-1.0, 0.0, 1.0))):
        raise _fail("core_wl_h", "plane sides -1, 0 or 1 after each entry's history")
    out["visc"] = get("visc", float, nt, "one per type of model_youngs")
    _within("core_visc", out["visc"], 0, np.inf, "damping coefficients >= 0")
    out["scalars"] = get("scalars", float, 4)
    _within("core_scalars", out["scalars"], -np.inf, np.inf, "finite time, time base, step, lost speed")
    if out["scalars"][3] < 0:
        raise _fail("core_scalars", "a lost particles' speed >= 0", out["scalars"][3])
    out["lost"] = get("lost", np.int64, len(LOST_PLACES), "one per place of LOST_PLACES")
    _within("core_lost", out["lost"], 0, np.inf, "counts >= 0")
    out["counters"] = counters = get("counters", np.int64, 5)
    step, lost, rebuilds, dirty, step_base = counters.tolist()
    if min(step, lost, rebuilds, step_base) < 0 or dirty not in (0, 1) or step_base > step:
        raise _fail("core_counters", "step, lost, rebuilds >= 0, dirty 0 or 1, 0 <= step base <= step")
    bounds = out["bounds"] = get("bounds", np.int32)
    # the bounds of the last pair loop: they end at n unless particles were added since (dirty:
    # the lists and bounds are made anew before the next pair loop)
    if (
        bounds.shape[0] < 2
        or bounds[0] != 0
        or np.any(np.diff(bounds) < 0)
        or not (bounds[-1] == n or (dirty and bounds[-1] <= n))
    ):
        raise _fail(
            "core_bounds",
            f"block bounds from 0, non-decreasing, up to the particle count {n} (at most, if dirty)",
        )
    # the solver's own entries
    next_id, next_wall, next_vertex = _entry(state, "counters", np.int64, 3).tolist()
    next_body = 0  # clumps made so far: absent without any
    if "clump_counter" in state:
        (next_body,) = _entry(state, "clump_counter", np.int64, 1).tolist()
    handles = _entry(state, "wall_handles", np.int64)
    kinds = _entry(state, "wall_kinds", np.int64, handles.shape[0], " (one per wall of wall_handles)")
    _within("wall_handles", handles, 0, next_wall, f"handles in [0, {next_wall})")
    _within("wall_kinds", kinds, 0, len(WALL_KINDS), "0 (plane), 1 (cylinder) or 2 (mesh)")
    walls = {int(h): WALL_KINDS[int(k)] for h, k in zip(handles, kinds)}
    if len(walls) != handles.shape[0]:
        raise _fail("wall_handles", "distinct handles", "repeated ones")
    owner = [walls.get(int(w)) for w in out["ewall"]]
    if any(o is None or WALL_KINDS.index(o) != k for o, k in zip(owner, ekind.tolist())):
        raise _fail("core_ewall", "the handle of a wall of the element's kind", "others")
    # stress and servo meshes (absent from checkpoints written before there were any)
    if "core_slots" not in state:
        state = {**state, "core_slots": np.zeros(0)}
    slots = out["slots"] = get("slots", float)
    if slots.shape[0] % SLOT_VALUES:
        raise _fail("core_slots", f"{SLOT_VALUES} values per stress mesh", slots.shape[0])
    _within("core_slots", slots, -np.inf, np.inf, "finite values")
    rows = slots.reshape(-1, SLOT_VALUES)
    meshes = [walls.get(int(w)) == "mesh" and w == int(w) for w in rows[:, SLOT.WALL]]
    if not all(meshes) or len(set(rows[:, SLOT.WALL])) != len(rows):
        raise _fail("core_slots", "one row per stress mesh, each naming a mesh wall", "others")
    if not np.all(np.isin(rows[:, SLOT.CONTROL], (0.0, 1.0, 2.0))):
        raise _fail("core_slots", "controls 0 (stress), 1 (force) or 2 (torque)", "others")
    if np.any(rows[:, SLOT.ARM] <= 0) or np.any((rows[:, SLOT.CONTROL] > 0) & (rows[:, SLOT.SET_POINT] == 0)):
        raise _fail("core_slots", "lever arms > 0 and servo set points != 0", "others")
    if "core_vib" not in state:  # nor vibrating ones
        state = {**state, "core_vib": np.zeros(0)}
    vib = out["vib"] = get("vib", float)
    if vib.shape[0] % VIBRATION_VALUES:
        raise _fail("core_vib", f"{VIBRATION_VALUES} values per vibrating mesh", vib.shape[0])
    _within("core_vib", vib, -np.inf, np.inf, "finite values")
    rows = vib.reshape(-1, VIBRATION_VALUES)
    if (
        not all(walls.get(int(w)) == "mesh" and w == int(w) for w in rows[:, VIBRATION.WALL])
        or len(set(rows[:, VIBRATION.WALL])) != len(rows)
        or not np.all(np.isin(rows[:, VIBRATION.KIND], (1.0, 2.0)))
        or not np.all(np.isin(rows[:, VIBRATION.ORDER], np.arange(1, HARMONICS + 1)))
    ):
        raise _fail(
            "core_vib",
            f"one row per vibrating mesh: its wall, kind 1 or 2, 1 to {HARMONICS} harmonics",
            "others",
        )
    if n and next_id <= ids.max() or ne and next_vertex <= out["evid"].max():
        raise _fail("counters", "next particle id and vertex beyond those in use", [next_id, next_vertex])
    _checked_clumps(state, out, nt, next_body)
    try:
        rng = json.loads(_text(state, "rng"))
        type(np.random.default_rng().bit_generator)().state = rng
    except (ValueError, TypeError, KeyError) as exc:
        raise _fail("rng", "the JSON state of a PCG64 generator", f"{type(exc).__name__}: {exc}") from None
    return tables, model, viscous, out, (next_id, next_wall, next_vertex, next_body), walls, rng


#: A checkpoint's per-clump entries (``core_body_<key>``) and their values per clump; the clump
#: entries are there only when there are clumps.
_BODY_VALUES = {"x": 3, "v": 3, "q": 4, "p": 3, "m": 1, "inertia": 3, "f": 3, "t": 3}


def _checked_clumps(state: Mapping[str, np.ndarray], out: dict, nt: int, next_body: int) -> None:
    """The clump entries of a state into ``out``, each checked (see :meth:`Solver.set_state`)."""
    n = out["r"].shape[0]
    if "core_mem" not in state:  # no clumps (the state of spheres only has no clump entries)
        return

    def get(key, dtype, length=None, basis=""):
        return _entry(state, f"core_{key}", dtype, length, basis and f" ({basis})")

    ids = out["body_id"] = get("body_id", np.int64)
    nb = ids.shape[0]
    _within("core_body_id", ids, 0, next_body, f"clump ids in [0, {next_body}) (counters)")
    if len(np.unique(ids)) != nb:
        raise _fail("core_body_id", "distinct clump ids", "repeated ids")
    for key, k in _BODY_VALUES.items():
        out[f"body_{key}"] = get(f"body_{key}", float, k * nb, f"{k} per clump of core_body_id")
        _within(f"core_body_{key}", out[f"body_{key}"], -np.inf, np.inf, "finite values")
    if np.any(out["body_m"] <= 0) or np.any(out["body_inertia"] <= 0):
        raise _fail("core_body_m", "clumps' masses and principal moments > 0")
    if np.any(np.abs(np.linalg.norm(out["body_q"].reshape(nb, 4), axis=1) - 1) > 1e-9):
        raise _fail("core_body_q", "unit quaternions")
    out["body_type"] = get("body_type", np.int32, nb, "one per clump of core_body_id")
    _within("core_body_type", out["body_type"], 0, nt, f"types in [0, {nt - 1}]")
    start = out["body_start"] = get("body_start", np.int32, nb + 1, "one more than the clumps")
    nm = int(start[-1]) if len(start) else 0
    _offsets("core_body_start", start, nm, "the member slots")
    if nb and np.any(np.diff(start) == 0):
        raise _fail("core_body_start", "at least one sphere per clump")
    for key in ("member_offset", "member_shift"):
        out[key] = get(key, float, 3 * nm, "3 per member slot of core_body_start")
        _within(f"core_{key}", out[key], -np.inf, np.inf, "finite values")
    mem = out["mem"] = get("mem", np.int32, n, "one per particle of core_r")
    if not np.array_equal(np.sort(mem[mem >= 0]), np.arange(nm)) or np.any(mem < -1):
        raise _fail("core_mem", f"-1 or a member slot, each of the {nm} slots held by one particle")
